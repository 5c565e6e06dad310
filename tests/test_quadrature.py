"""Deterministic sphere quadratures: exactness, convergence, adaptivity, bad input."""

from math import gamma

import numpy as np
import pytest

from sns_np.quadrature import adaptive_sphere_integral, sphere_quadrature
from sns_np.shapes import SphericalHarmonic


def monomial_integral(a, b, c):
    """Closed form of the integral of x^a y^b z^c over the unit sphere."""
    if a % 2 or b % 2 or c % 2:
        return 0.0
    return 2 * gamma((a + 1) / 2) * gamma((b + 1) / 2) * gamma((c + 1) / 2) / gamma(
        (a + b + c + 3) / 2)


@pytest.mark.parametrize("rule", ["gauss", "gauss-theta"])
def test_nodes_and_weights(rule):
    p, w = sphere_quadrature(12, 20, rule=rule)
    assert p.shape == (240, 3) and w.shape == (240,)
    np.testing.assert_allclose(np.linalg.norm(p, axis=1), 1.0, atol=1e-15)
    assert np.all(w > 0)
    assert abs(w.sum() - 4 * np.pi) < 1e-12
    assert np.abs(p[:, 2]).max() < 1 - 1e-4  # no node on a pole
    assert sphere_quadrature(5)[0].shape == (50, 3)  # n_phi defaults to 2 n_theta


def test_gauss_is_exact_up_to_its_degree():
    n_theta, n_phi = 6, 12  # exact up to degree min(11, 11)
    p, w = sphere_quadrature(n_theta, n_phi)
    for a in range(12):
        for b in range(12 - a):
            for c in range(12 - a - b):
                val = w @ (p[:, 0] ** a * p[:, 1] ** b * p[:, 2] ** c)
                assert abs(val - monomial_integral(a, b, c)) < 1e-13, (a, b, c)
    # and not beyond it, in either direction
    assert abs(w @ p[:, 2] ** 12 - monomial_integral(0, 0, 12)) > 1e-6
    assert abs(w @ p[:, 0] ** 12 - monomial_integral(12, 0, 0)) > 1e-6


def test_spherical_harmonics_are_orthonormal():
    p, w = sphere_quadrature(12, 24)  # exact for products up to degree 23
    lm = [(l, m) for l in range(7) for m in range(-l, l + 1)]
    Y = np.stack([SphericalHarmonic(l, m).jet(p, 0) for l, m in lm])
    G = (Y * w) @ Y.T
    np.testing.assert_allclose(G, np.eye(len(lm)), atol=1e-13)


def test_gauss_theta_is_spectral_for_odd_powers_of_theta():
    exact = 2 * np.pi * (np.pi**3 - 6 * np.pi)  # integral of theta^3 over the sphere
    errs = {}
    for rule in ("gauss", "gauss-theta"):
        p, w = sphere_quadrature(20, 4, rule=rule)
        errs[rule] = abs(w @ np.arccos(p[:, 2]) ** 3 - exact)
    assert errs["gauss-theta"] < 1e-12
    assert errs["gauss"] > 1e-3  # algebraic convergence only, in z = cos(theta)


def test_adaptive_integral_resolves_a_narrow_peak():
    sigma = 0.01
    p0 = np.array([0.3, -0.4, np.sqrt(0.75)])
    exact = np.pi * sigma**2 * (1 - np.exp(-4 / sigma**2))

    def f(p):
        return np.exp(-np.sum((p - p0) ** 2, axis=1) / sigma**2)

    value, info = adaptive_sphere_integral(f, atol=1e-12)
    assert info["converged"] and abs(value - exact) < 1e-12
    # a fixed product grid with as many nodes is far off
    n = int(np.sqrt(info["points"] / 2))
    p, w = sphere_quadrature(n)
    assert abs(w @ f(p) - exact) > 1e-3 * exact
    # the budget is honoured and reported
    _, info = adaptive_sphere_integral(f, atol=1e-14, max_points=50_000)
    assert not info["converged"] and info["points"] <= 50_000


def test_adaptive_symmetry():
    def f(p):
        phi = np.arctan2(p[:, 1], p[:, 0])
        return np.cos(6 * phi) ** 2 * (1 + p[:, 2] ** 2) + np.exp(p[:, 2])

    full, _ = adaptive_sphere_integral(f, atol=1e-11)
    sector, info = adaptive_sphere_integral(f, atol=1e-11, symmetry=6)
    assert info["converged"] and abs(full - sector) < 1e-10
    exact = np.pi * (2 + 2 / 3) + 2 * np.pi * (np.e - 1 / np.e)
    assert abs(full - exact) < 1e-10


def test_bad_input():
    with pytest.raises(ValueError, match="n_theta"):
        sphere_quadrature(0)
    with pytest.raises(ValueError, match="rule"):
        sphere_quadrature(4, rule="lebedev")
    with pytest.raises(ValueError, match="atol"):
        adaptive_sphere_integral(lambda p: p[:, 0], atol=-1.0)
    with pytest.raises(ValueError, match="shape"):
        adaptive_sphere_integral(lambda p: p, atol=1e-3)
    with pytest.raises(ValueError, match="finite"):
        adaptive_sphere_integral(lambda p: np.full(len(p), np.nan), atol=1e-3)
