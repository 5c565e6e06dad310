"""Analytic surface maps: exact jets, formulas, poles, meshes, bad input."""

import numpy as np
import pytest

from sns_np.errors import ShapeError
from sns_np.mesh import icosphere
from sns_np.shapes import (
    SMALL_SCALES,
    Bobble,
    Ellipsoid,
    Flower,
    LinearShape,
    PerturbedEllipsoid,
    Sphere,
    Spike,
    Tree,
    radial_shape,
)
from sns_np.testing import check_jet

RADIAL = [Flower, Bobble, Spike, Tree]
ALL_SHAPES = [Sphere(1.7), Ellipsoid(3.0, 2.0, 0.5), PerturbedEllipsoid()] + [
    c() for c in RADIAL] + [c.small() for c in RADIAL]


def random_points(n, seed, rmin=0.5, rmax=2.0):
    g = np.random.default_rng(seed)
    p = g.standard_normal((n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p * g.uniform(rmin, rmax, (n, 1))


def g_reference(family, theta, phi):
    """The issue's formulas, written independently of sns_np (plain numpy)."""
    Q = (theta * (np.pi - theta)) ** 2
    t, f = theta, phi
    return {
        "flower": 0.3 * (0.4 * Q * np.cos(18 * t) ** 2 + 0.6 * Q * np.sin(6 * f + 18 * t) ** 2),
        "bobble": 0.1 * (0.4 * Q * np.cos(12 * t) ** 2 + 0.4 * Q * np.sin(12 * f + 6 * t) ** 2),
        "spike": 0.4 * np.sin(t) ** 2 * np.sin(6 * t) * np.sin(6 * f),
        "tree": 0.05 * (2 * t**3 * np.sin(6 * t) ** 2 + 0.6 * Q * np.sin(6 * f + 6 * t**2) ** 2),
    }[family]


@pytest.mark.parametrize("S", ALL_SHAPES, ids=repr)
def test_jets_match_central_differences(S):
    x = random_points(40, 1)  # off the sphere too: the maps live on R^3
    err = check_jet(S, x, order=2, h=1e-4, richardson=True)
    assert err["J"] < 1e-8 and err["D2"] < 1e-8, err
    assert err["D2_symmetry"] < 1e-14


@pytest.mark.parametrize("S", ALL_SHAPES, ids=repr)
def test_jet_orders_are_consistent(S):
    x = random_points(10, 2)
    y0 = S.jet(x, 0)
    y1, J1 = S.jet(x, 1)
    y2, J2, D2 = S.jet(x, 2)
    assert y0.shape == (10, 3) and J1.shape == (10, 3, 3) and D2.shape == (10, 3, 3, 3)
    np.testing.assert_array_equal(y0, y1)
    np.testing.assert_array_equal(y1, y2)
    np.testing.assert_array_equal(J1, J2)
    np.testing.assert_array_equal(S(x), y0)
    # the 3 x 3 Jacobian is invertible and orientation preserving, like a network's
    assert np.all(np.linalg.det(J1) > 0) and np.all(np.linalg.cond(J1) < 1e3)


def test_linear_shapes():
    x = random_points(5, 3)
    y, J, D2 = Ellipsoid(3.0, 2.0, 0.5).jet(x, 2)
    np.testing.assert_allclose(y, x * [3.0, 2.0, 0.5])
    np.testing.assert_array_equal(J, np.broadcast_to(np.diag([3.0, 2.0, 0.5]), (5, 3, 3)))
    assert not D2.any()
    np.testing.assert_allclose(Sphere(2.5)(x), 2.5 * x)
    A = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.3], [0.1, 0.0, 1.0]])
    np.testing.assert_allclose(LinearShape(A)(x), x @ A.T)


@pytest.mark.parametrize("cls", RADIAL)
def test_radial_surface_matches_formula(cls):
    s = SMALL_SCALES[cls.family]
    p = random_points(500, 4, 1.0, 1.0)
    theta = np.arccos(np.clip(p[:, 2], -1, 1))
    phi = np.arctan2(p[:, 1], p[:, 0])
    expected = s * (1 + g_reference(cls.family, theta, phi))[:, None] * p
    np.testing.assert_allclose(cls(s)(p), expected, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("cls", RADIAL)
def test_radial_map_is_one_homogeneous(cls):
    S = cls(0.9)
    p = random_points(50, 5, 1.0, 1.0)
    y, J, D2 = S.jet(p, 2)
    np.testing.assert_allclose(S(3.0 * p), 3.0 * y, rtol=1e-13)
    # Euler: J x = S(x) (so the radial derivative never vanishes), D2[x] = 0
    np.testing.assert_allclose(np.einsum("kia,ka->ki", J, p), y, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.einsum("kiab,kb->kia", D2, p), 0.0, atol=1e-10)


@pytest.mark.data
def test_flower_mesh_vertices_lie_on_flower(mesh_dir):
    path = mesh_dir / "flower_mesh5.obj"
    V = np.array([line.split()[1:4] for line in path.read_text().splitlines()
                  if line.startswith("v ")], dtype=float)
    assert V.shape == (10242, 3)
    P = V / np.linalg.norm(V, axis=1, keepdims=True)
    err = np.abs(Flower()(P) - V).max() / np.abs(V).max()
    assert err < 1e-12
    # and not on a differently scaled or perturbed flower
    assert np.abs(Flower(1.001)(P) - V).max() > 1e-4
    assert np.abs(Bobble()(P) - V).max() > 1e-2


def test_radial_shape_names():
    for fam, cls in [("FLOWER", Flower), ("BOBBLE", Bobble), ("SPIKE", Spike), ("TREE", Tree)]:
        big, small = radial_shape(fam), radial_shape("SMALL" + fam)
        assert type(big) is cls and big.scale == 1.0
        assert type(small) is cls and small.scale == SMALL_SCALES[fam.lower()]
    assert SMALL_SCALES == {"flower": 0.366, "bobble": 0.679, "spike": 0.772, "tree": 0.301}
    assert radial_shape("smallflower").scale == 0.366
    with pytest.raises(ValueError, match="unknown radial shape"):
        radial_shape("STAR")


# --- the poles ---------------------------------------------------------------------------

def _ring(t, n, north=True):
    """n points at angle t from a pole, phi offset so that no symmetry aliases the average."""
    phi = 0.123 + 2 * np.pi * np.arange(n) / n
    z = np.cos(t) if north else -np.cos(t)
    return np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.full(n, z)], 1)


@pytest.mark.parametrize("cls", RADIAL)
@pytest.mark.parametrize("north", [True, False])
def test_pole_jets(cls, north):
    S = cls()
    pole = np.array([[0.0, 0.0, 1.0 if north else -1.0]])
    G = S.radius_function(pole, 2)
    assert G.v[0] == 0 and not G.g.any()  # g and its gradient vanish at both poles
    assert np.all(np.isfinite(S.jet(pole, 2)[2]))
    c = S.pole_c[0 if north else 1]
    np.testing.assert_allclose(G.h[0], np.diag([2 * c, 2 * c, 0.0]), atol=1e-14)
    # c is the limit of the phi-averaged g / t^2 (Richardson over t and t/2)
    avg = [S.radius_function(_ring(t, 97, north), 0).v.mean() / t**2 for t in (2e-5, 1e-5)]
    np.testing.assert_allclose(2 * avg[1] - avg[0], c, rtol=1e-6, atol=1e-9)
    # and the pole Hessian is the limit of the phi-averaged Hessians
    h = S.radius_function(_ring(1e-6, 97, north), 2).h.mean(axis=0)
    np.testing.assert_allclose(h, G.h[0], rtol=0, atol=1e-4 * max(1.0, c))


@pytest.mark.parametrize("north", [True, False])
def test_spike_is_twice_differentiable_at_the_poles(north):
    S = Spike()
    sign = 1.0 if north else -1.0
    _, J0, D20 = S.jet(np.array([[0.0, 0.0, sign]]), 2)
    for t in (1e-4, 1e-6):
        _, J, D2 = S.jet(_ring(t, 11, north), 2)
        assert np.abs(J - J0).max() < 100 * t**2 and np.abs(D2 - D20).max() < 100 * t


def test_other_families_are_not_twice_differentiable_at_the_poles():
    # the Hessian of G has a direction-dependent limit (documented), unlike SPIKE's
    for cls in (Flower, Bobble, Tree):
        h = cls().radius_function(_ring(1e-7, 24), 2).h
        assert np.ptp(h[:, 0, 0]) > 1.0
    assert np.ptp(Spike().radius_function(_ring(1e-7, 24), 2).h[:, 0, 0]) < 1e-4


@pytest.mark.parametrize("cls", RADIAL)
def test_jets_are_accurate_next_to_the_poles(cls):
    """Against 40-digit symbolic derivatives in x, y, z (sympy + mpmath)."""
    sp = pytest.importorskip("sympy")
    mpmath = pytest.importorskip("mpmath")
    x, y, z = sp.symbols("x y z", real=True)
    th = sp.atan2(sp.sqrt(x**2 + y**2), z)
    ph = sp.atan2(y, x)
    Q = (th * (sp.pi - th)) ** 2
    g = {
        "flower": sp.Rational(3, 10) * (sp.Rational(2, 5) * Q * sp.cos(18 * th) ** 2
                                        + sp.Rational(3, 5) * Q * sp.sin(6 * ph + 18 * th) ** 2),
        "bobble": sp.Rational(1, 10) * (sp.Rational(2, 5) * Q * sp.cos(12 * th) ** 2
                                        + sp.Rational(2, 5) * Q * sp.sin(12 * ph + 6 * th) ** 2),
        "spike": sp.Rational(2, 5) * sp.sin(th) ** 2 * sp.sin(6 * th) * sp.sin(6 * ph),
        "tree": sp.Rational(1, 20) * (2 * th**3 * sp.sin(6 * th) ** 2
                                      + sp.Rational(3, 5) * Q * sp.sin(6 * ph + 6 * th**2) ** 2),
    }[cls.family]
    X = (x, y, z)
    exprs = [g] + [sp.diff(g, a) for a in X] + [sp.diff(g, a, b) for a in X for b in X]
    fn = sp.lambdify(X, exprs, modules="mpmath")
    pts = np.concatenate([_ring(t, 3, north) for t in (1e-3, 1e-5, 1e-7)
                          for north in (True, False)])
    G = cls().radius_function(pts, 2)
    with mpmath.workdps(40):
        ref = np.array([[float(v) for v in fn(*(mpmath.mpf(float(c)) for c in q))]
                        for q in pts])
    ours = np.concatenate([G.v[:, None], G.g, G.h.reshape(-1, 9)], axis=1)
    scale = np.maximum(np.abs(ref).max(axis=0), 1.0)
    # forming pi - theta from theta loses ~1e-16 / rho here (2e-9 at 1e-7, south pole)
    assert np.max(np.abs(ours - ref) / scale) < 1e-12


# --- meshes and bad input ----------------------------------------------------------------

@pytest.mark.parametrize("S", [Ellipsoid(2.0, 1.0, 0.5), Flower(), Spike.small()], ids=repr)
def test_mesh_vertices_on_the_surface(S):
    V, F = S.mesh(3)
    P, F0 = icosphere(3)
    np.testing.assert_array_equal(F, F0)
    assert V.shape == P.shape and np.all(np.isfinite(V))
    np.testing.assert_allclose(V, S(P), rtol=0, atol=0)
    # the icosphere has vertices exactly at both poles; the jets are finite there
    poles = np.flatnonzero(np.abs(np.abs(P[:, 2]) - 1) < 1e-15)
    assert poles.size == 2
    assert all(np.all(np.isfinite(a)) for a in S.jet(P[poles], 2))


def test_bad_input():
    with pytest.raises(ValueError, match="origin"):
        Flower().jet(np.zeros((2, 3)), 1)
    with pytest.raises(ShapeError):
        Sphere().jet(np.ones((4, 2)), 0)
    with pytest.raises(ShapeError):
        Flower().jet(np.array([[np.nan, 0.0, 1.0]]), 0)
    with pytest.raises(ValueError, match="order"):
        Ellipsoid().jet(np.ones((1, 3)), 3)
    with pytest.raises(ValueError, match="radius"):
        Sphere(-1.0)
    with pytest.raises(ValueError, match="fold"):
        PerturbedEllipsoid(1.0, 1.0, 1.0, amplitude=0.5, frequency=3.0)
    with pytest.raises(ValueError, match="scale"):
        Flower(0.0)
    with pytest.raises(ValueError):
        LinearShape(np.eye(2))
    with pytest.raises(ValueError, match="level"):
        Sphere().mesh(-1)


def test_perturbed_ellipsoid_is_not_homogeneous():
    # second derivatives along the radial direction are non-zero: geometry must use them right
    S = PerturbedEllipsoid()
    p = random_points(20, 6, 1.0, 1.0)
    _, J, D2 = S.jet(p, 2)
    radial = np.einsum("kiab,ka,kb->ki", D2, p, p)
    assert np.abs(radial).max() > 0.05
    assert np.abs(np.einsum("kia,ka->ki", J, p) - S(p)).max() > 0.01


def test_ellipsoid_foot_point_from_anywhere():
    """The demo's closest-point solver: on the ellipsoid, orthogonal residual, no blow-up."""
    from sns_np.demo import AXES, ellipsoid_foot_point, ellipsoid_geometry

    g = np.random.default_rng(7)
    d = g.standard_normal((3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.concatenate([np.full(1000, 1e-3), g.uniform(0.2, 3.0, 1000), np.full(1000, 50.0)])
    x = d * r[:, None]  # deep inside (where plain Newton from t = 0 diverged), around, far out
    with np.errstate(all="raise"):
        y = ellipsoid_foot_point(x)
        n, H, K = ellipsoid_geometry(y)
    a = np.asarray(AXES)
    # (deep inside, a^2 + t is tiny and y = x a^2 / (a^2 + t) loses digits: 1e-9, not 1e-15)
    assert np.abs(((y / a) ** 2).sum(axis=1) - 1.0).max() < 1e-9
    res = x - y  # the residual of a closest point is normal to the surface
    tang = res - np.einsum("ij,ij->i", res, n)[:, None] * n
    assert np.abs(tang).max() < 1e-10 * max(1.0, np.abs(res).max())
    # never farther than the nearest of the six axis points (a lower bound on optimality)
    cand = np.concatenate([np.diag(a), -np.diag(a)])
    dist_axis = np.linalg.norm(x[:, None, :] - cand[None], axis=2).min(axis=1)
    assert np.all(np.linalg.norm(res, axis=1) <= dist_axis + 1e-12)
    assert np.all(np.isfinite(H)) and np.all(K > 0)
