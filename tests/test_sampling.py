"""Sphere sampling, rejection sampling by area and Monte Carlo / quadrature integrals.

References are closed forms (ellipsoid area by Legendre's elliptic-integral formula, spheroid
band areas by 1D quadrature, spherical-harmonic orthonormality and eigenvalues) or an
independent discretisation (cotangent FEM Dirichlet energy on a fine mesh).
"""

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.optimize
import scipy.special
import scipy.stats

from sns_np.errors import DegenerateMapError, ShapeError
from sns_np.sampling import (
    Estimate,
    SurfaceSample,
    area,
    fibonacci_sphere,
    inner_product,
    integrate,
    l2_norm,
    rayleigh_quotient,
    rejection_sample,
    surface_sample,
    uniform_sphere,
)
from sns_np.shapes import Ellipsoid, LinearShape, PerturbedEllipsoid, Sphere, SphericalHarmonic


def ellipsoid_area(a, b, c):
    """Legendre's closed form for the area of an ellipsoid with semi-axes a >= b >= c."""
    a, b, c = sorted((a, b, c), reverse=True)
    phi = math.acos(c / a)
    m = a * a * (b * b - c * c) / (b * b * (a * a - c * c))
    E = scipy.special.ellipeinc(phi, m)
    F = scipy.special.ellipkinc(phi, m)
    s = math.sin(phi)
    return 2 * math.pi * c * c + 2 * math.pi * a * b / s * (E * s * s + F * (1 - s * s))


# ------------------------------------------------------------------------------ sphere points

def test_uniform_sphere_is_unit_seeded_and_isotropic():
    p = uniform_sphere(20000, rng=3)
    assert p.shape == (20000, 3)
    assert np.allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-14)
    assert np.array_equal(p, uniform_sphere(20000, rng=3))
    assert np.array_equal(uniform_sphere(10), uniform_sphere(10, rng=0))  # None means seed 0
    se = math.sqrt(1 / 3 / 20000)  # std of a coordinate is sqrt(1/3)
    assert np.all(np.abs(p.mean(axis=0)) < 5 * se)
    # E[x^2] = 1/3, std of x^2 is sqrt(1/5 - 1/9)
    assert np.all(np.abs((p ** 2).mean(axis=0) - 1 / 3) < 5 * math.sqrt(4 / 45 / 20000))


def test_fibonacci_sphere_is_unit_and_integrates_better_than_mc():
    p = fibonacci_sphere(2000)
    assert np.allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-14)
    Y = SphericalHarmonic(3, 1)  # zero mean on the sphere
    err_fib = abs(Y.jet(p, 0).mean()) * 4 * math.pi
    err_mc = abs(Y.jet(uniform_sphere(2000, rng=0), 0).mean()) * 4 * math.pi
    assert err_fib < 1e-3
    assert err_fib < 0.1 * err_mc
    assert abs(4 * math.pi * (p[:, 0] * p[:, 1]) .mean()) < 1e-3
    assert abs(4 * math.pi * (p[:, 2] ** 2).mean() - 4 * math.pi / 3) < 1e-5


# ------------------------------------------------------------------------------ rejection

def spheroid_cells(a, c, n_bands):
    """Band edges in z = p_z of equal surface area on the spheroid diag(a, a, c)."""
    d = lambda t: a * math.sqrt(c * c * (1 - t * t) + a * a * t * t)  # area element
    total = scipy.integrate.quad(d, -1, 1, epsabs=1e-13)[0]
    cum = lambda t: scipy.integrate.quad(d, -1, t, epsabs=1e-13)[0]
    edges = [-1.0]
    for i in range(1, n_bands):
        edges.append(scipy.optimize.brentq(lambda t: cum(t) - i * total / n_bands, -1, 1))
    return np.array(edges + [1.0]), 2 * math.pi * total


def cell_counts(p, edges, n_sectors=4):
    band = np.clip(np.searchsorted(edges, p[:, 2]) - 1, 0, len(edges) - 2)
    phi = np.mod(np.arctan2(p[:, 1], p[:, 0]), 2 * math.pi)
    sector = np.minimum((phi / (2 * math.pi) * n_sectors).astype(int), n_sectors - 1)
    return np.bincount(band * n_sectors + sector, minlength=(len(edges) - 1) * n_sectors)


def test_rejection_sample_is_uniform_in_area_chi_square():
    a, c = 1.0, 2.5
    edges, total_area = spheroid_cells(a, c, 10)
    s = rejection_sample(Ellipsoid(a, a, c), 20000, rng=7)
    assert np.allclose(np.linalg.norm(s.p, axis=1), 1.0, atol=1e-14)  # on the sphere
    assert np.allclose(s.x, s.p * [a, a, c])
    counts = cell_counts(s.p, edges)
    assert scipy.stats.chisquare(counts).pvalue > 1e-3
    # the test has power: sphere-uniform points (no rejection) fail it decisively
    assert scipy.stats.chisquare(cell_counts(uniform_sphere(len(s), rng=7), edges)).pvalue < 1e-10
    # expected count n_target, area estimated from the proposals
    assert abs(len(s) - 20000) < 5 * math.sqrt(20000)
    assert abs(s.area - total_area) < 5 * s.area_stderr
    assert np.allclose(s.weights, s.area / len(s))


def test_rejection_sample_means_match_area_weighted_integrals():
    S = PerturbedEllipsoid()
    s = rejection_sample(S, 20000, rng=1)
    q = surface_sample(S, 40000, method="quadrature")
    f = lambda x: x[:, 0] ** 2 + x[:, 1]
    exact = (q.weights @ f(q.x)) / q.area
    vals = f(s.x)
    assert abs(vals.mean() - exact) < 5 * vals.std() / math.sqrt(len(s))


def test_rejection_sample_draws_more_proposals_instead_of_clipping():
    # a needle: area element ratio ~ 20, so 10x oversampling is not enough for n_target
    S = Ellipsoid(0.05, 0.05, 1.0)
    s = rejection_sample(S, 3000, rng=0, oversample=1.0)
    assert s.n_proposed > 3000
    assert abs(len(s) - 3000) < 5 * math.sqrt(3000)
    with pytest.raises(ValueError, match="max_proposals"):
        rejection_sample(S, 3000, rng=0, oversample=1.0, max_proposals=4000)


# ------------------------------------------------------------------------------ integrals

def test_area_quadrature_and_mc_against_closed_form():
    S = Ellipsoid(1.0, 1.3, 0.7)
    exact = ellipsoid_area(1.0, 1.3, 0.7)
    q = area(S, 20000, method="quadrature")
    assert abs(q.value - exact) < 1e-10 * exact
    assert math.isnan(q.stderr)
    mc = area(S, 50000, rng=2)
    assert 0 < mc.stderr < 0.01 * exact
    assert abs(mc.value - exact) < 4 * mc.stderr
    rj = area(S, 5000, method="rejection", rng=2)
    assert abs(rj.value - exact) < 4 * rj.stderr


def test_monte_carlo_error_shrinks_like_one_over_sqrt_n():
    S = Ellipsoid(1.0, 1.3, 0.7)
    field = lambda p: p[:, 0] ** 2 + p[:, 1] + 0.5
    ref = integrate(S, field, 20000, method="quadrature").value
    sizes = np.array([250, 2500, 25000])
    rms, mean_se = [], []
    for n in sizes:
        ests = [integrate(S, field, int(n), rng=seed) for seed in range(30)]
        err = np.array([e.value - ref for e in ests])
        rms.append(math.sqrt(np.mean(err ** 2)))
        mean_se.append(np.mean([e.stderr for e in ests]))
    slope = np.polyfit(np.log(sizes), np.log(rms), 1)[0]
    assert -0.65 < slope < -0.35
    # the reported standard errors describe the observed errors
    ratio = np.array(rms) / np.array(mean_se)
    assert np.all((ratio > 0.6) & (ratio < 1.5))


def test_inner_products_norms_and_rayleigh_quotient_on_the_sphere():
    S = Sphere(2.0)  # radius 2: <Y, Y> = 4, Q(Y_lm) = l(l+1) / 4
    s = surface_sample(S, 5000, method="quadrature")
    Y21, Y2m1, Y30 = SphericalHarmonic(2, 1), SphericalHarmonic(2, -1), SphericalHarmonic(3, 0)
    assert abs(inner_product(S, Y21, Y21, sample=s).value - 4.0) < 1e-12
    assert abs(inner_product(S, Y21, Y2m1, sample=s).value) < 1e-12
    assert abs(l2_norm(S, Y30, sample=s).value - 2.0) < 1e-12
    assert abs(rayleigh_quotient(S, Y30, sample=s).value - 3.0) < 1e-12
    est = rayleigh_quotient(S, Y21, 20000, rng=4)
    assert abs(est.value - 1.5) < 4 * est.stderr
    assert est.stderr < 0.03


def test_rayleigh_quotient_on_ellipsoid_matches_fem_dirichlet_energy():
    from sns_np.mesh import cotan_laplacian, icosphere, mass_matrix

    S = Ellipsoid(1.0, 1.3, 0.7)
    g = lambda p: p[:, 0] + p[:, 1] * p[:, 2]
    field = type("F", (), {"jet": staticmethod(lambda p, order=0: (
        g(p) if order == 0 else (g(p), np.stack([np.ones(len(p)), p[:, 2], p[:, 1]], 1))))})()
    Q = rayleigh_quotient(S, field, 20000, method="quadrature").value
    P, F = icosphere(6)
    V = S(P)
    u = g(P)
    Q_fem = (u @ (-cotan_laplacian(V, F) @ u)) / (u @ (mass_matrix(V, F, "full") @ u))
    assert abs(Q - Q_fem) < 1e-3 * Q


def test_sample_subset_keeps_integrals_unbiased():
    s = surface_sample(Sphere(), 4000, rng=0)
    sub = s.subset(np.arange(0, 4000, 4))
    assert len(sub) == 1000
    assert abs(sub.weights.sum() - s.weights[::4].sum() * 4) < 1e-12
    assert abs(sub.area - s.area) == 0


# ------------------------------------------------------------------------------ bad input

def test_bad_inputs_raise_clear_errors():
    S = Sphere()
    with pytest.raises(ValueError, match="n must be"):
        uniform_sphere(-1)
    with pytest.raises(ValueError, match="oversample"):
        rejection_sample(S, 10, oversample=0.5)
    with pytest.raises(ValueError, match="method"):
        area(S, 100, method="simpson")
    with pytest.raises(ShapeError, match=r"shape \(100,\)"):
        integrate(S, lambda p: np.ones((len(p), 2)), 100)
    bad_field = type("B", (), {"jet": lambda self, p, order=0: np.ones(len(p) + 1)})()
    with pytest.raises(ShapeError, match="value of shape"):
        integrate(S, bad_field, 100)
    with pytest.raises(TypeError, match="field protocol"):
        rayleigh_quotient(S, lambda p: p[:, 0], 100)
    with pytest.raises(DegenerateMapError, match="degenerate"):
        area(LinearShape(np.diag([1.0, 0.0, 0.0])), 100)
    with pytest.raises(DegenerateMapError):
        rejection_sample(LinearShape(np.diag([0.0, 0.0, 1.0])), 100)
    s = surface_sample(S, 50, rng=0)
    with pytest.raises(ShapeError, match=r"\(50,\)"):
        s.integral(np.ones(49))
    with pytest.raises(TypeError, match="SurfaceSample"):
        area(S, sample=np.zeros((3, 3)))


def test_estimate_behaves_like_a_number():
    e = Estimate(1.5, 0.1)
    assert float(e) == 1.5 and e.stderr == 0.1
    assert isinstance(surface_sample(Sphere(), 10, rng=0), SurfaceSample)
