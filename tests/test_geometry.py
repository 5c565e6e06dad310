"""Differential quantities against closed forms, an independent symbolic chart, Gauss-Bonnet."""

import numpy as np
import pytest

from sns_np import geometry as geo
from sns_np.errors import DegenerateMapError, ShapeError
from sns_np.quadrature import adaptive_sphere_integral, sphere_quadrature
from sns_np.shapes import (
    Bobble,
    Ellipsoid,
    Flower,
    LinearShape,
    PerturbedEllipsoid,
    Sphere,
    Spike,
    Tree,
)


def sphere_points(n, seed=0):
    g = np.random.default_rng(seed)
    p = g.standard_normal((n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


POLES = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


class DirectionalWrapper:
    """A map that offers directional jets (computed from the full jet) and records the calls."""

    def __init__(self, surface):
        self.surface, self.calls = surface, []

    def jet(self, p, order, directions=None, second=None):
        if directions is None:
            self.calls.append(("full", order))
            return self.surface.jet(p, order)
        m = directions.shape[2]
        k = m if second is None else second
        self.calls.append(("directional", order, m, k))
        out = self.surface.jet(p, order)
        JD = np.einsum("kia,kam->kim", out[1], directions)
        if order == 1:
            return out[0], JD
        Dk = directions[:, :, :k]
        return out[0], JD, np.einsum("kiab,kap,kbq->kipq", out[2], Dk, Dk)


class FullOnly:
    def __init__(self, surface):
        self.surface = surface

    def jet(self, p, order):
        return self.surface.jet(p, order)


# --- the frame ----------------------------------------------------------------------------

def test_tangent_frame():
    p = np.concatenate([sphere_points(500, 1), POLES,
                        [[0.0, np.sqrt(0.75), 0.5], [0.0, np.sqrt(0.75), -0.5]]])
    R = geo.tangent_frame(p)
    assert R.shape == (len(p), 3, 2)
    np.testing.assert_allclose(np.einsum("kia,kib->kab", R, R), np.broadcast_to(np.eye(2), (
        len(p), 2, 2)), atol=1e-15)
    np.testing.assert_allclose(np.einsum("kia,ki->ka", R, p), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.cross(R[:, :, 0], R[:, :, 1]), p, atol=1e-15)
    # the paper's matrix away from the poles: e_u = d/dtheta, e_v = d/dphi / sin(theta)
    q = p[np.abs(p[:, 2]) < 0.5]
    th, ph = np.arccos(q[:, 2]), np.arctan2(q[:, 1], q[:, 0])
    paper = np.stack([np.stack([np.cos(th) * np.cos(ph), -np.sin(ph)], 1),
                      np.stack([np.cos(th) * np.sin(ph), np.cos(ph)], 1),
                      np.stack([-np.sin(th), 0 * th], 1)], 1)
    np.testing.assert_allclose(geo.tangent_frame(q), paper, atol=1e-14)


def test_points_are_validated():
    with pytest.raises(ShapeError, match="unit sphere"):
        geo.differential_quantities(Sphere(), [[0.0, 0.0, 1.1]])
    with pytest.raises(ShapeError, match="shape"):
        geo.differential_quantities(Sphere(), np.ones((3, 2)))
    with pytest.raises(ShapeError, match="non-finite"):
        geo.tangent_frame([[np.nan, 0.0, 1.0]])
    # within the tolerance: projected onto the sphere
    q = geo.differential_quantities(Sphere(), [[0.0, 0.0, 1.0 + 5e-7]])
    np.testing.assert_array_equal(q.x, [[0.0, 0.0, 1.0]])


# --- spheres and ellipsoids -------------------------------------------------------------------

@pytest.mark.parametrize("r", [1.0, 0.3, 2.5])
def test_sphere(r):
    p = np.concatenate([sphere_points(300, 2), POLES])
    q = geo.differential_quantities(Sphere(r), p)
    np.testing.assert_allclose(q.x, r * p, atol=1e-15)
    np.testing.assert_allclose(q.n, p, atol=1e-14)
    for v, exact in [(q.H, 1 / r), (q.K, 1 / r**2), (q.kmin, 1 / r), (q.kmax, 1 / r),
                     (q.area_element, r**2)]:
        np.testing.assert_allclose(v, exact, rtol=1e-13)
    np.testing.assert_allclose(q.II, q.I / r, atol=1e-13)
    np.testing.assert_allclose(q.I, r**2 * np.broadcast_to(np.eye(2), q.I.shape), atol=1e-13)
    assert q.valid.all()


def ellipsoid_closed_form(a, b, c, x):
    """Textbook curvatures of x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 at surface points x."""
    s = x[:, 0] ** 2 / a**4 + x[:, 1] ** 2 / b**4 + x[:, 2] ** 2 / c**4
    K = 1 / ((a * b * c) ** 2 * s**2)
    H = (a * a + b * b + c * c - np.sum(x**2, axis=1)) / (2 * (a * b * c) ** 2 * s**1.5)
    n = x / np.array([a * a, b * b, c * c])
    return H, K, n / np.linalg.norm(n, axis=1, keepdims=True)


def test_ellipsoid_against_closed_form():
    a, b, c = 3.0, 1.5, 0.6
    p = np.concatenate([sphere_points(5000, 3), POLES])
    q = geo.differential_quantities(Ellipsoid(a, b, c), p)
    H, K, n = ellipsoid_closed_form(a, b, c, q.x)
    assert np.abs(q.H - H).max() / np.abs(H).max() < 1e-9
    assert np.abs(q.K - K).max() / np.abs(K).max() < 1e-9
    assert np.abs(q.n - n).max() < 1e-9
    np.testing.assert_allclose(q.kmin * q.kmax, q.K, rtol=1e-9)


def check_principal_frame(q, JR):
    """Directions: unit, tangent, orthogonal, dmin x dmax = n, normal curvatures kmin/kmax."""
    for d in (q.dmin, q.dmax):
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.einsum("ki,ki->k", d, q.n), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(q.dmin, q.dmax), q.n, atol=1e-10)
    assert np.all(q.kmin <= q.kmax)
    np.testing.assert_array_equal(q.H, 0.5 * (q.kmin + q.kmax))
    for d, k in ((q.dmin, q.kmin), (q.dmax, q.kmax)):
        w = np.linalg.lstsq  # solve JR w = d per point (JR has full column rank)
        W = np.stack([w(JR[i], d[i], rcond=None)[0] for i in range(len(d))])
        kn = np.einsum("ka,kab,kb->k", W, q.II, W) / np.einsum("ka,kab,kb->k", W, q.I, W)
        np.testing.assert_allclose(kn, k, rtol=1e-9, atol=1e-9 * np.abs(k).max())


@pytest.mark.parametrize("S", [Ellipsoid(3.0, 1.5, 0.6), PerturbedEllipsoid(), Spike()],
                         ids=repr)
def test_principal_directions(S):
    p = sphere_points(200, 4)
    q = geo.differential_quantities(S, p)
    _, J = S.jet(p, 1)
    check_principal_frame(q, geo.tangent_jacobian(J, geo.tangent_frame(p)))


def test_ellipsoid_area_against_carlson():
    special = pytest.importorskip("scipy.special")
    a, b, c = 3.0, 1.5, 0.6
    exact = 4 * np.pi * a * b * c * special.elliprg(1 / a**2, 1 / b**2, 1 / c**2)
    p, w = sphere_quadrature(60)
    assert abs(w @ geo.area_element(Ellipsoid(a, b, c), p) - exact) < 1e-12 * exact


# --- radial shapes against an independent symbolic (theta, phi) chart --------------------------

def chart_reference(cls):
    """H, K, n and principal directions from sympy derivatives of the (theta, phi) chart."""
    sp = pytest.importorskip("sympy")
    th, ph = sp.symbols("theta phi", real=True)
    Q = (th * (sp.pi - th)) ** 2
    R = sp.Rational
    g = {
        Flower: R(3, 10) * (R(2, 5) * Q * sp.cos(18 * th) ** 2
                            + R(3, 5) * Q * sp.sin(6 * ph + 18 * th) ** 2),
        Bobble: R(1, 10) * (R(2, 5) * Q * sp.cos(12 * th) ** 2
                            + R(2, 5) * Q * sp.sin(12 * ph + 6 * th) ** 2),
        Spike: R(2, 5) * sp.sin(th) ** 2 * sp.sin(6 * th) * sp.sin(6 * ph),
        Tree: R(1, 20) * (2 * th**3 * sp.sin(6 * th) ** 2
                          + R(3, 5) * Q * sp.sin(6 * ph + 6 * th**2) ** 2),
    }[cls]
    X = (1 + g) * sp.Matrix([sp.sin(th) * sp.cos(ph), sp.sin(th) * sp.sin(ph), sp.cos(th)])
    parts = [X, X.diff(th), X.diff(ph), X.diff(th, 2), X.diff(th, ph), X.diff(ph, 2)]
    fn = sp.lambdify((th, ph), [e for M in parts for e in M], modules="numpy", cse=True)

    def evaluate(theta, phi, s):
        vals = [np.broadcast_to(v, theta.shape) for v in fn(theta, phi)]
        x, Xt, Xp, Xtt, Xtp, Xpp = (s * np.stack(vals[3 * i:3 * i + 3], 1) for i in range(6))
        n = np.cross(Xt, Xp)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        E, F, G = (np.sum(u * v, axis=1) for u, v in ((Xt, Xt), (Xt, Xp), (Xp, Xp)))
        # II with the convex-positive sign of DESIGN.md: II_ab = -n . X_ab
        e, f, g2 = (-np.sum(n * u, axis=1) for u in (Xtt, Xtp, Xpp))
        det = E * G - F * F
        K = (e * g2 - f * f) / det
        H = (E * g2 - 2 * F * f + G * e) / (2 * det)
        Ws = np.linalg.solve(np.stack([np.stack([E, F], 1), np.stack([F, G], 1)], 1),
                             np.stack([np.stack([e, f], 1), np.stack([f, g2], 1)], 1))
        lam, vec = np.linalg.eig(Ws)
        order = np.argsort(lam.real, axis=1)
        vec = np.take_along_axis(vec.real, order[:, None, :], axis=2)
        dirs = [Xt * vec[:, 0:1, j] + Xp * vec[:, 1:2, j] for j in range(2)]
        dirs = [d / np.linalg.norm(d, axis=1, keepdims=True) for d in dirs]
        return x, n, H, K, np.sort(lam.real, axis=1), dirs

    return evaluate


@pytest.mark.parametrize("cls", [Flower, Bobble, Spike, Tree])
@pytest.mark.parametrize("small", [False, True])
def test_radial_shapes_against_symbolic_chart(cls, small):
    S = cls.small() if small else cls()
    g = np.random.default_rng(5)
    theta = g.uniform(0.15, np.pi - 0.15, 400)
    phi = g.uniform(-np.pi, np.pi, 400)
    p = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
    x, n, H, K, k, (dmin, dmax) = chart_reference(cls)(theta, phi, S.scale)
    q = geo.differential_quantities(S, p)
    np.testing.assert_allclose(q.x, x, atol=1e-12)
    assert np.abs(q.n - n).max() < 1e-9
    assert np.abs(q.H - H).max() / np.abs(H).max() < 1e-9
    assert np.abs(q.K - K).max() / np.abs(K).max() < 1e-9
    assert np.abs(q.kmin - k[:, 0]).max() / np.abs(k).max() < 1e-9
    assert np.abs(q.kmax - k[:, 1]).max() / np.abs(k).max() < 1e-9
    apart = (k[:, 1] - k[:, 0]) > 1e-3 * np.abs(k).max()  # directions are defined
    assert apart.sum() > 300
    for ours, ref in ((q.dmin, dmin), (q.dmax, dmax)):
        assert np.abs(1 - np.abs(np.sum(ours * ref, axis=1)))[apart].max() < 1e-9


# --- Gauss-Bonnet ----------------------------------------------------------------------------

def total_curvature_product(S, n):
    p, w = sphere_quadrature(n)
    q = geo.differential_quantities(S, p)
    return w @ (q.K * q.area_element)


@pytest.mark.parametrize("S", [Sphere(0.7), Ellipsoid(3.0, 1.5, 0.6), PerturbedEllipsoid(),
                               LinearShape([[1.0, 0.4, 0.0], [0.0, 1.0, 0.3], [0.2, 0, 0.5]])],
                         ids=repr)
def test_gauss_bonnet_smooth_maps(S):
    assert abs(total_curvature_product(S, 80) / (4 * np.pi) - 1) < 1e-10


def test_gauss_bonnet_spike_product_rule():
    assert abs(total_curvature_product(Spike(), 300) / (4 * np.pi) - 1) < 1e-6


def _total_curvature_adaptive(S, symmetry):
    def KdA(p):
        q = geo.differential_quantities(S, p)
        return q.K * q.area_element

    value, info = adaptive_sphere_integral(KdA, atol=1e-5 * 4 * np.pi, symmetry=symmetry,
                                           initial=(16, 2))
    assert info["converged"]
    return value


@pytest.mark.parametrize("S,symmetry", [(Spike(), 6), (Spike.small(), 6), (Bobble(), 24),
                                        (Bobble.small(), 24), (Tree(), 12),
                                        (Tree.small(), 12)], ids=repr)
def test_gauss_bonnet_radial(S, symmetry):
    assert abs(_total_curvature_adaptive(S, symmetry) / (4 * np.pi) - 1) < 1e-6


@pytest.mark.slow
def test_gauss_bonnet_flower():  # ~15 s: over 200 narrow pits to resolve
    assert abs(_total_curvature_adaptive(Flower(), 12) / (4 * np.pi) - 1) < 1e-6


def test_total_curvature_density_does_not_depend_on_scale():
    # K dA is scale-free (K ~ 1/s^2, dA ~ s^2), so Gauss-Bonnet on Flower covers Flower.small
    # once the two densities agree pointwise
    p = sphere_points(2000, 3)
    a = geo.differential_quantities(Flower(), p)
    b = geo.differential_quantities(Flower.small(), p)
    np.testing.assert_allclose(b.K * b.area_element, a.K * a.area_element, rtol=1e-9,
                               atol=1e-9 * np.abs(a.K * a.area_element).max())


def test_flower_area():
    # README of the shared meshes: exact area 239.7829 (4 decimals)
    value, info = adaptive_sphere_integral(lambda p: geo.area_element(Flower(), p), atol=1e-6,
                                           symmetry=12, initial=(16, 2))
    assert info["converged"] and abs(value - 239.7829) < 6e-5
    p, w = sphere_quadrature(100)
    assert abs(w @ geo.area_element(Flower.small(), p) - 0.366**2 * value) < 1e-3


# --- directional vs full jets, small functions, from-jets functions ---------------------------

@pytest.mark.parametrize("S", [PerturbedEllipsoid(), Tree.small()], ids=repr)
def test_directional_and_full_jets_give_identical_geometry(S):
    p = sphere_points(100, 6)
    wrapped = DirectionalWrapper(S)
    a = geo.differential_quantities(wrapped, p)
    b = geo.differential_quantities(FullOnly(S), p)
    assert wrapped.calls == [("directional", 2, 3, 2)]  # 1 + 3 + 3 streams, one call
    for name in ("x", "n", "I", "II", "H", "K", "kmin", "kmax", "dmin", "dmax",
                 "area_element"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-13,
                                   atol=1e-13, err_msg=name)
    wrapped.calls.clear()
    np.testing.assert_allclose(geo.normals(wrapped, p), a.n, atol=1e-14)
    assert wrapped.calls == [("directional", 1, 2, 2)]


def test_small_functions_and_from_jets_agree():
    S = PerturbedEllipsoid()
    p = sphere_points(50, 7)
    q = geo.differential_quantities(S, p)
    np.testing.assert_allclose(geo.normals(S, p), q.n, atol=1e-14)
    np.testing.assert_allclose(geo.first_fundamental_form(S, p), q.I, atol=1e-14)
    np.testing.assert_allclose(geo.area_element(S, p), q.area_element, atol=1e-14)
    np.testing.assert_array_equal(geo.second_fundamental_form(S, p), q.II)
    np.testing.assert_array_equal(geo.mean_curvature(S, p), q.H)
    np.testing.assert_array_equal(geo.gaussian_curvature(S, p), q.K)
    np.testing.assert_array_equal(np.stack(geo.principal_curvatures(S, p)),
                                  np.stack([q.kmin, q.kmax]))
    np.testing.assert_array_equal(np.stack(geo.principal_directions(S, p)),
                                  np.stack([q.dmin, q.dmax]))
    # from full ambient jets, without another call into the map
    _, J, D2 = S.jet(p, 2)
    R = geo.tangent_frame(p)
    JR, S2 = geo.frame_jets(J, D2, R, p)
    n = geo.normals_from_jets(JR)
    I = geo.first_fundamental_form_from_jets(JR)
    II = geo.second_fundamental_form_from_jets(S2, n)
    H, K, kmin, kmax = geo.curvatures_from_forms(I, II)
    for mine, ref in ((n, q.n), (I, q.I), (II, q.II), (H, q.H), (K, q.K), (kmin, q.kmin),
                      (geo.area_element_from_jets(JR), q.area_element)):
        np.testing.assert_allclose(mine, ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.einsum("kab,kbc->kac", geo.inverse_metric(I), I),
                               np.broadcast_to(np.eye(2), I.shape), atol=1e-12)
    np.testing.assert_allclose(geo.metric_conditioning(I),
                               np.sqrt(np.linalg.eigvalsh(I)[:, 0] / np.linalg.eigvalsh(I)[:, 1]),
                               rtol=1e-12)


def test_chunking_does_not_change_results():
    S = Bobble.small()
    p = sphere_points(101, 8)
    a = geo.differential_quantities(S, p)
    b = geo.differential_quantities(S, p, chunk=7)
    for name in ("x", "n", "H", "K", "dmin", "area_element"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_orientation_reversing_map_flips_normal_and_curvature():
    q = geo.differential_quantities(LinearShape(np.diag([-1.0, 1.0, 1.0])), sphere_points(20))
    np.testing.assert_allclose(q.n, -q.x, atol=1e-14)  # inward normal
    np.testing.assert_allclose(q.H, -1.0, rtol=1e-14)
    np.testing.assert_allclose(q.K, 1.0, rtol=1e-14)


# --- degenerate and broken maps --------------------------------------------------------------

def test_degenerate_map_raises_or_flags():
    flat = LinearShape(np.diag([1.0, 1.0, 0.0]))  # squashes the sphere onto a disc
    p = np.concatenate([sphere_points(10, 9), [[1.0, 0.0, 0.0]], sphere_points(5, 10)])
    with pytest.raises(DegenerateMapError, match="point 10 "):
        geo.differential_quantities(flat, p)
    q = geo.differential_quantities(flat, p, on_degenerate="nan")
    assert q.valid.tolist() == [True] * 10 + [False] + [True] * 5
    for name in ("n", "I", "II", "H", "K", "kmin", "kmax", "dmin", "dmax", "area_element"):
        v = getattr(q, name)
        assert np.all(np.isnan(v[10])) and np.all(np.isfinite(v[q.valid])), name
    assert np.all(np.isfinite(q.x))
    with pytest.raises(DegenerateMapError, match="point 3 "):  # global index across chunks
        geo.differential_quantities(flat, p[7:], chunk=2)
    with pytest.raises(ValueError, match="on_degenerate"):
        geo.differential_quantities(flat, p, on_degenerate="ignore")


class BrokenMap:
    def __init__(self, kind):
        self.kind = kind

    def jet(self, p, order):
        out = Sphere().jet(p, order)
        if self.kind == "shape":
            return (out[0][:, :2],) + tuple(out[1:])
        out[-1][0] = np.nan
        return out


@pytest.mark.parametrize("kind,match", [("shape", "shape"), ("nan", "non-finite")])
def test_broken_maps_fail_loudly(kind, match):
    with pytest.raises(ShapeError, match=match):
        geo.differential_quantities(BrokenMap(kind), sphere_points(4))
    with pytest.raises(TypeError):
        geo.differential_quantities(object(), sphere_points(4))
