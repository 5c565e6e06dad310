"""The Laplace-Beltrami operator: closed forms, method and domain agreement, Green's identity."""

import numpy as np
import pytest

from sns_np import geometry as geo
from sns_np.errors import DegenerateMapError, ShapeError
from sns_np.quadrature import sphere_quadrature
from sns_np.shapes import (
    Bobble,
    ComponentField,
    Ellipsoid,
    Flower,
    LinearField,
    LinearShape,
    PerturbedEllipsoid,
    PullbackField,
    SineWaveField,
    Sphere,
    SphericalHarmonic,
    Spike,
    Tree,
    coordinate_field,
)
from sns_np.testing import check_jet

METHODS = ["divgrad", "mean_curvature"]
DOMAINS = ["sphere", "ambient"]


def sphere_points(n, seed=0):
    g = np.random.default_rng(seed)
    p = g.standard_normal((n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


POLES = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def coordinate_fields(S, domain):
    if domain == "ambient":
        return [coordinate_field(i) for i in range(3)]
    return [ComponentField(S, i) for i in range(3)]  # g(p) = S(p)_i on the sphere


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("domain", DOMAINS)
def test_unit_sphere_coordinates(method, domain):
    S = Sphere()
    p = np.concatenate([sphere_points(200, 1), POLES])
    lap = np.stack([geo.laplace_beltrami(S, p, f, method, domain)
                    for f in coordinate_fields(S, domain)], axis=1)
    np.testing.assert_allclose(lap, -2 * p, atol=1e-13)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("l", range(0, 7))
def test_unit_sphere_harmonics_are_eigenfunctions(method, l):
    S = Sphere()
    p = np.concatenate([sphere_points(100, 2), POLES])
    for m in range(-l, l + 1):
        Y = SphericalHarmonic(l, m)
        y = Y.jet(p, 0)
        for domain in DOMAINS:  # on the unit sphere S(p) = p: both domains see the same field
            lap = geo.laplace_beltrami(S, p, Y, method, domain)
            np.testing.assert_allclose(lap, -l * (l + 1) * y, atol=1e-11 * max(1, l * l),
                                       err_msg=f"l={l} m={m} {domain}")


@pytest.mark.parametrize("method", METHODS)
def test_sphere_of_radius_r(method):
    r, l = 2.5, 3
    S = Sphere(r)
    p = sphere_points(100, 3)
    Y = SphericalHarmonic(l, -1)
    # sphere domain: h(r p) = Y(p); ambient: the solid harmonic r^l Y(p) at r p
    np.testing.assert_allclose(geo.laplace_beltrami(S, p, Y, method, "sphere"),
                               -l * (l + 1) / r**2 * Y.jet(p, 0), atol=1e-12)
    np.testing.assert_allclose(geo.laplace_beltrami(S, p, Y, method, "ambient"),
                               -l * (l + 1) / r**2 * r**l * Y.jet(p, 0), atol=1e-10)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("domain", DOMAINS)
def test_ellipsoid_coordinates_give_mean_curvature_normal(method, domain):
    a, b, c = 3.0, 1.5, 0.6
    S = Ellipsoid(a, b, c)
    p = np.concatenate([sphere_points(2000, 4), POLES])
    x = S(p)
    s = x[:, 0] ** 2 / a**4 + x[:, 1] ** 2 / b**4 + x[:, 2] ** 2 / c**4
    H = (a * a + b * b + c * c - np.sum(x**2, axis=1)) / (2 * (a * b * c) ** 2 * s**1.5)
    n = x / np.array([a * a, b * b, c * c])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    lap = np.stack([geo.laplace_beltrami(S, p, f, method, domain)
                    for f in coordinate_fields(S, domain)], axis=1)
    expected = -2 * H[:, None] * n
    assert np.abs(lap - expected).max() / np.abs(expected).max() < 1e-9


@pytest.mark.parametrize("S", [PerturbedEllipsoid(), Spike.small(), Flower(), Bobble(),
                               Tree.small()], ids=repr)
def test_methods_and_domains_agree(S):
    p = sphere_points(300, 5)
    f = SineWaveField(frequency=4.0, chirp=2.0)
    out = {(m, d): geo.laplace_beltrami(S, p, f, m, d) for m in METHODS for d in DOMAINS}
    # an ambient field and its pullback to the sphere are the same surface field
    pulled = geo.laplace_beltrami(S, p, PullbackField(f, S), "divgrad", "sphere")
    for d in DOMAINS:
        ref = out["divgrad", d]
        scale = np.abs(ref).max()
        assert np.abs(out["mean_curvature", d] - ref).max() < 1e-10 * scale, d
    assert np.abs(pulled - out["divgrad", "ambient"]).max() < 1e-10 * np.abs(pulled).max()
    # and the two fields differ, so the comparisons above are not vacuous
    assert np.abs(out["divgrad", "sphere"] - out["divgrad", "ambient"]).max() > 0.1
    # Delta x = -2 H n on the same shape
    q = geo.differential_quantities(S, p)
    lap = np.stack([geo.laplace_beltrami(S, p, ComponentField(S, i)) for i in range(3)], 1)
    assert np.abs(lap + 2 * q.H[:, None] * q.n).max() < 1e-9 * np.abs(q.H).max()


def test_greens_identities():
    """int Delta f dA = 0 and int g Delta f dA = -int grad f . grad g dA on a closed surface."""
    S = PerturbedEllipsoid()
    p, w = sphere_quadrature(60)
    dA = w * geo.area_element(S, p)
    f, g = SineWaveField(frequency=2.0, chirp=1.0), SphericalHarmonic(2, 1)
    for domain in DOMAINS:
        for method in METHODS:
            lf = geo.laplace_beltrami(S, p, f, method, domain)
            lg = geo.laplace_beltrami(S, p, g, method, domain)
            x = p if domain == "sphere" else S(p)
            fv, gv = f.jet(x, 0), g.jet(x, 0)
            gf = geo.surface_gradient(S, p, f, domain)
            gg = geo.surface_gradient(S, p, g, domain)
            dirichlet = dA @ np.einsum("ki,ki->k", gf, gg)
            assert abs(dA @ lf) < 1e-10 * (dA @ np.abs(lf))
            assert abs(dA @ (gv * lf) + dirichlet) < 1e-10 * abs(dirichlet)
            assert abs(dA @ (fv * lg) + dirichlet) < 1e-10 * abs(dirichlet)


def test_surface_gradient_and_divergence():
    S = PerturbedEllipsoid()
    p = sphere_points(200, 6)
    q = geo.differential_quantities(S, p)
    f = SineWaveField()
    ga = geo.surface_gradient(S, p, f, "ambient")
    gs = geo.surface_gradient(S, p, PullbackField(f, S), "sphere")
    np.testing.assert_allclose(gs, ga, atol=1e-12)
    np.testing.assert_allclose(np.einsum("ki,ki->k", ga, q.n), 0.0, atol=1e-12)
    # unit sphere: grad_S z = e_z - z p
    gz = geo.surface_gradient(Sphere(), p, coordinate_field(2), "ambient")
    np.testing.assert_allclose(gz, np.array([0, 0, 1.0]) - p[:, 2:3] * p, atol=1e-14)
    # the position field has div_S x = 2 on every surface, in both domains
    identity = LinearShape(np.eye(3))
    np.testing.assert_allclose(geo.surface_divergence(S, p, identity, "ambient"), 2, rtol=1e-12)
    np.testing.assert_allclose(geo.surface_divergence(S, p, S, "sphere"), 2, rtol=1e-12)
    # a normal field phi n has div_S (phi n) = 2 H phi: the unit normal of the unit sphere
    np.testing.assert_allclose(geo.surface_divergence(Sphere(), p, identity, "sphere"), 2)
    np.testing.assert_allclose(geo.surface_divergence(Sphere(0.5), p, identity, "sphere"), 4)


class DirectionalWrapper:
    """A map that offers directional jets (from its full jet) and records the calls."""

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


class Normalise:
    """S(x) = x / |x|: the unit sphere, but the 3 x 3 Jacobian (I - x x^T / r^2) / r is singular."""

    def jet(self, x, order):
        x = np.asarray(x, dtype=float)
        r = np.linalg.norm(x, axis=1)
        y = x / r[:, None]
        if order == 0:
            return y
        eye = np.eye(3)
        J = (eye - y[:, :, None] * y[:, None, :]) / r[:, None, None]
        if order == 1:
            return y, J
        u = y / r[:, None]  # x / r^2
        D2 = (-(eye[None, :, :, None] * u[:, None, None, :] + eye[None, :, None, :]
                * u[:, None, :, None] + eye[None, None, :, :] * u[:, :, None, None])
              + 3 * y[:, :, None, None] * y[:, None, :, None] * u[:, None, None, :]) / r[
            :, None, None, None]
        return y, J, D2


def test_singular_jacobian():
    S = Normalise()
    assert check_jet(S, 1.5 * sphere_points(10, 7), richardson=True)["D2"] < 1e-8
    p = sphere_points(20, 8)
    f = ComponentField(S, 0)
    with pytest.raises(DegenerateMapError, match="point 0 .*3 x 3 Jacobian"):
        geo.laplace_beltrami(S, p, f, "mean_curvature", "sphere")
    # divgrad needs only derivatives along the sphere, and the surface is regular
    np.testing.assert_allclose(geo.laplace_beltrami(S, p, f, "divgrad", "sphere"),
                               -2 * p[:, 0], atol=1e-13)
    np.testing.assert_allclose(geo.laplace_beltrami(S, p, coordinate_field(0),
                                                    "mean_curvature", "ambient"), -2 * p[:, 0],
                               atol=1e-13)


def test_degenerate_surface_and_bad_input():
    flat = LinearShape(np.diag([1.0, 1.0, 0.0]))
    p = np.concatenate([sphere_points(3, 9), [[0.0, 1.0, 0.0]]])
    for method in METHODS:
        with pytest.raises(DegenerateMapError, match="point 3 "):
            geo.laplace_beltrami(flat, p, coordinate_field(0), method, "ambient")
    with pytest.raises(DegenerateMapError):
        geo.surface_gradient(flat, p, coordinate_field(0))
    with pytest.raises(ValueError, match="method"):
        geo.laplace_beltrami(Sphere(), p, coordinate_field(0), method="cotan")
    with pytest.raises(ValueError, match="domain"):
        geo.laplace_beltrami(Sphere(), p, coordinate_field(0), domain="mesh")
    with pytest.raises(ShapeError, match="unit sphere"):
        geo.laplace_beltrami(Sphere(), 2 * p, coordinate_field(0))

    class BadField:
        def jet(self, x, order):
            return np.zeros(len(x)), np.zeros((len(x), 3)), np.zeros((len(x), 3))

    with pytest.raises(ShapeError, match="Hessian"):
        geo.laplace_beltrami(Sphere(), p, BadField())


def test_directional_path_and_chunking():
    S = Tree.small()
    p = sphere_points(50, 10)
    f = SineWaveField()
    wrapped = DirectionalWrapper(S)
    a = geo.laplace_beltrami(wrapped, p, f)
    assert wrapped.calls == [("directional", 2, 3, 2)]
    np.testing.assert_allclose(a, geo.laplace_beltrami(S, p, f), rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(geo.laplace_beltrami(S, p, f, chunk=9),
                                  geo.laplace_beltrami(S, p, f))
    wrapped.calls.clear()
    geo.laplace_beltrami(wrapped, p, f, "mean_curvature", "sphere")
    assert wrapped.calls == [("full", 2)]  # the extension g o S^-1 needs the full jet
    lin = LinearField([1.0, -1.0, 2.0])
    np.testing.assert_allclose(geo.laplace_beltrami(Ellipsoid(2, 1, 1), POLES, lin, "divgrad",
                                                    "ambient"),
                               geo.laplace_beltrami(Ellipsoid(2, 1, 1), POLES, lin,
                                                    "mean_curvature", "ambient"), atol=1e-12)
