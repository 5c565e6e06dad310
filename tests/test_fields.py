"""Neural scalar fields: jets, save/load, and the hand-written gradients of the eigen losses.

Every derivative is checked against central differences (sns_np.testing).
"""

import math

import numpy as np
import pytest

from sns_np.errors import ModelFileError, ShapeError
from sns_np.fields import NeuralField
from sns_np.nn import ResidualMLP
from sns_np.sampling import rayleigh_quotient, rejection_sample, surface_sample
from sns_np.shapes import PerturbedEllipsoid, Sphere, SphericalHarmonic
from sns_np.spectral import eigen_loss, orthogonality_loss, rayleigh_loss, unit_norm_loss
from sns_np.testing import check_gradient, check_jet

from .conftest import NOJIT, sphere_points


def lively_field(seed=3, **kw):
    f = NeuralField(seed=seed, **kw)
    f.net.W3[...] *= 50.0  # the default initialisation is nearly constant and tiny
    return f


def test_field_architecture_is_the_papers():
    f = NeuralField()
    assert (f.net.width, f.net.depth, f.net.out_dim, f.net.bias) == (10, 2, 3, False)
    assert f.n_params == 3 * 10 + 2 * 2 * 100 + 10 * 3


def test_field_jets_match_central_differences():
    f = lively_field(scale=1.7)
    x = 1.1 * sphere_points(20, seed=1)
    err = check_jet(f, x, order=2, richardson=True)
    assert err["J"] < 1e-8 and err["D2"] < 1e-8
    v, g, H = f.jet(x, 2)
    assert v.shape == (20,) and g.shape == (20, 3) and H.shape == (20, 3, 3)
    # the scalar is the mean of the network's 3 outputs, times the scale
    assert np.allclose(v, 1.7 * f.net.jet(x, 0).mean(axis=1), rtol=1e-14)
    assert np.array_equal(f(x), v) and np.array_equal(f.value(x), v)


def test_field_save_load_round_trip(tmp_path):
    f = lively_field(seed=5, scale=0.3)
    path = f.save(tmp_path / "field.npz")
    g = NeuralField.load(path)
    x = sphere_points(7)
    assert np.array_equal(f(x), g(x)) and g.scale == 0.3
    ResidualMLP(width=4, depth=1).save(tmp_path / "net.npz")
    with pytest.raises(ModelFileError, match="NeuralField"):
        NeuralField.load(tmp_path / "net.npz")
    with pytest.raises(ModelFileError, match="does not exist"):
        NeuralField.load(tmp_path / "missing.npz")


@pytest.fixture(scope="module")
def sample():
    return rejection_sample(PerturbedEllipsoid(), 60, rng=0)


def previous_modes(s):
    return np.stack([np.full(len(s), 1 / math.sqrt(s.area)),
                     SphericalHarmonic(1, 0).jet(s.p, 0), SphericalHarmonic(2, 1).jet(s.p, 0)],
                    axis=1)


@pytest.mark.parametrize("which", ["total", "rayleigh", "ortho", "reg"])
def test_loss_gradients_match_central_differences(sample, which):
    f = lively_field()
    P = previous_modes(sample)

    def fun(theta):
        f.net.unpack(theta)
        if which == "total":
            loss, grad = eigen_loss(f, sample, P, lambda_ortho=3.0, lambda_reg=2.0)
            return loss.total, grad
        if which == "rayleigh":
            return rayleigh_loss(f, sample)
        if which == "ortho":
            return orthogonality_loss(f, sample, P)
        return unit_norm_loss(f, sample)

    # every parameter with the JIT; 3 random directions without it (pure Python is slow)
    nd = 3 if NOJIT else None
    assert check_gradient(fun, f.net.pack(), h=1e-5, n_directions=nd, rng=1,
                          richardson=True) < 1e-7


def test_loss_gradient_on_the_blas_path(sample):
    # width > 32 takes the chunked BLAS engine: forward jet, then vjp
    f = lively_field(width=40, depth=1)
    P = previous_modes(sample)

    def fun(theta):
        f.net.unpack(theta)
        loss, grad = eigen_loss(f, sample, P, lambda_ortho=5.0, lambda_reg=1.0)
        return loss.total, grad

    assert check_gradient(fun, f.net.pack(), h=1e-5, n_directions=3 if NOJIT else 12, rng=0,
                          richardson=True) < 1e-7


def test_loss_terms_agree_with_the_sampling_estimators(sample):
    f = lively_field(seed=8)
    P = previous_modes(sample)
    loss, _ = eigen_loss(f, sample, P, lambda_ortho=2.0, lambda_reg=3.0)
    q = rayleigh_quotient(None, f, sample=sample).value  # full-jet path, not the engine's
    v = f(sample.p)
    norm = math.sqrt(sample.weights @ v ** 2)
    c = (sample.weights * v) @ P
    assert abs(loss.rayleigh - q) < 1e-12 * q
    assert abs(loss.norm - norm) < 1e-12
    assert abs(loss.ortho - c @ c) < 1e-12 * max(1.0, c @ c)
    assert abs(loss.total - (q + 2.0 * (c @ c) + 3.0 * (norm - 1) ** 2)) < 1e-10


@pytest.mark.slow_nojit
def test_rayleigh_loss_matches_spherical_harmonic_spectrum_on_sphere():
    # Parseval on the unit sphere: Q(g) = sum l(l+1) c_lm^2 / sum c_lm^2 (an independent
    # route through the harmonic coefficients of the field, no derivatives of the network)
    from sns_np.spectral import real_sh

    f = lively_field(seed=2)
    s = surface_sample(Sphere(), 8000, method="quadrature")
    q_engine = rayleigh_loss(f, s)[0]
    c = real_sh(s.p, 24).T @ (s.weights * f(s.p))
    l = np.floor(np.sqrt(np.arange(c.size)))
    q_spectral = (c ** 2 @ (l * (l + 1))) / (c @ c)
    assert abs(q_engine - q_spectral) < 1e-8 * q_spectral


def test_loss_input_errors(sample):
    f = NeuralField(seed=0)
    n = len(sample)
    with pytest.raises(ShapeError, match=rf"\({n}, k\)"):
        eigen_loss(f, sample, np.ones((n - 1, 2)))
    with pytest.raises(TypeError, match="NeuralField"):
        eigen_loss(SphericalHarmonic(1, 0), sample)
    with pytest.raises(TypeError, match="SurfaceSample"):
        eigen_loss(f, sample.p)
    with pytest.raises(ValueError, match="lambda_ortho"):
        eigen_loss(f, sample, lambda_ortho=-1.0)
    with pytest.raises(ShapeError):
        f.jet(np.ones((4, 2)))


@pytest.mark.skipif(NOJIT, reason="timing-independent but slow without the JIT")
def test_field_evaluates_large_batches():
    f = NeuralField(seed=1)
    assert f(sphere_points(50000)).shape == (50000,)
