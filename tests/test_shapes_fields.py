"""Analytic scalar fields: exact jets, spherical harmonics against scipy, pullbacks."""

import numpy as np
import pytest

from sns_np.errors import ShapeError
from sns_np.shapes import (
    ComponentField,
    Flower,
    LinearField,
    PerturbedEllipsoid,
    PullbackField,
    SineWaveField,
    SphericalHarmonic,
    coordinate_field,
)
from sns_np.testing import check_jet


def random_points(n, seed, rmin=0.5, rmax=2.0):
    g = np.random.default_rng(seed)
    p = g.standard_normal((n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p * g.uniform(rmin, rmax, (n, 1))


FIELDS = [
    LinearField([1.0, -2.0, 0.5], 0.3), coordinate_field(1), SphericalHarmonic(0, 0),
    SphericalHarmonic(3, -2), SphericalHarmonic(5, 5), SphericalHarmonic(6, 1),
    SineWaveField(), SineWaveField(frequency=7.0, chirp=-3.0, direction=[0, 1, 1]),
    PullbackField(SineWaveField(), PerturbedEllipsoid()), ComponentField(Flower(), 2),
]


@pytest.mark.parametrize("f", FIELDS, ids=lambda f: type(f).__name__)
def test_field_jets_match_central_differences(f):
    x = random_points(30, 1)
    err = check_jet(f, x, order=2, h=1e-4, richardson=True)
    assert err["J"] < 1e-8 and err["D2"] < 1e-8, err
    v0 = f.jet(x, 0)
    v1, g1 = f.jet(x, 1)
    v2, g2, H2 = f.jet(x, 2)
    assert v0.shape == (30,) and g1.shape == (30, 3) and H2.shape == (30, 3, 3)
    np.testing.assert_array_equal(v0, v2)
    np.testing.assert_array_equal(g1, g2)


def real_sh_scipy(l, m, p):
    """Real Y_lm without the Condon-Shortley phase, from scipy's complex harmonics."""
    special = pytest.importorskip("scipy.special")
    theta = np.arccos(np.clip(p[:, 2], -1, 1))
    phi = np.arctan2(p[:, 1], p[:, 0])
    Y = special.sph_harm_y(l, abs(m), theta, phi)  # includes (-1)^m
    if m == 0:
        return Y.real
    sign = (-1.0) ** abs(m)
    return np.sqrt(2) * sign * (Y.imag if m < 0 else Y.real)


@pytest.mark.parametrize("l", range(0, 8))
def test_spherical_harmonics_match_scipy(l):
    pytest.importorskip("scipy.special")
    p = random_points(200, 2, 1.0, 1.0)
    for m in range(-l, l + 1):
        np.testing.assert_allclose(SphericalHarmonic(l, m).jet(p, 0), real_sh_scipy(l, m, p),
                                   atol=1e-12, err_msg=f"l={l}, m={m}")


@pytest.mark.parametrize("lm", [(2, 0), (3, 2), (4, -3), (7, 7)])
def test_solid_harmonic_extension(lm):
    # the ambient extension is the homogeneous harmonic polynomial r^l Y(x / r)
    Y = SphericalHarmonic(*lm)
    l = lm[0]
    x = random_points(50, 3)
    v, g, H = Y.jet(x, 2)
    np.testing.assert_allclose(Y.jet(2.5 * x, 0), 2.5**l * v, rtol=1e-12)
    np.testing.assert_allclose(np.trace(H, axis1=1, axis2=2), 0.0, atol=1e-10 * np.abs(H).max())
    np.testing.assert_allclose(np.einsum("ka,ka->k", g, x), l * v, atol=1e-12 * np.abs(v).max())


def test_sine_wave_formula():
    f = SineWaveField(frequency=3.0, chirp=1.5, direction=[1, 2, 2], chirp_direction=[0, 3, -4],
                      phase=0.3)
    x = random_points(20, 4)
    u = 3.0 * x @ (np.array([1, 2, 2]) / 3) + 1.5 * (x @ np.array([0, 0.6, -0.8])) ** 2 + 0.3
    np.testing.assert_allclose(f.jet(x, 0), np.sin(u), rtol=1e-13, atol=1e-14)


def test_pullback_and_component_fields():
    S = PerturbedEllipsoid()
    f = SineWaveField()
    p = random_points(30, 5, 1.0, 1.0)
    np.testing.assert_allclose(PullbackField(f, S).jet(p, 0), f.jet(S(p), 0), rtol=1e-14)
    for i in range(3):
        np.testing.assert_array_equal(ComponentField(S, i).jet(p, 0), S(p)[:, i])
        np.testing.assert_allclose(PullbackField(coordinate_field(i), S).jet(p, 2)[2],
                                   S.jet(p, 2)[2][:, i], atol=1e-14)


def test_bad_field_input():
    with pytest.raises(ValueError, match="l must"):
        SphericalHarmonic(-1)
    with pytest.raises(ValueError, match="m must"):
        SphericalHarmonic(2, 3)
    with pytest.raises(ValueError, match="coordinate index"):
        coordinate_field(3)
    with pytest.raises(ValueError, match="component index"):
        ComponentField(Flower(), -1)
    with pytest.raises(ValueError, match="shape"):
        LinearField([1.0, 2.0])
    with pytest.raises(ValueError, match="direction"):
        SineWaveField(direction=[0, 0, 0])
    with pytest.raises(ShapeError):
        SineWaveField().jet(np.ones((3, 4)), 0)
