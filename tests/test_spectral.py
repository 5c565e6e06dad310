"""Laplace-Beltrami eigenmodes: Rayleigh-Ritz, the paper's neural method, the FEM reference.

References: the unit sphere's closed-form spectrum (l(l+1), multiplicity 2l+1), SciPy's
spherical harmonics, the Laplace-Beltrami operator of sns_np.geometry (an independent code
path: second derivatives in a chart) and cotangent FEM on refined meshes.
"""

import math

import numpy as np
import pytest
from scipy.special import sph_harm_y

from sns_np.errors import DegenerateMapError, DivergenceError
from sns_np.fields import NeuralField
from sns_np.geometry import laplace_beltrami
from sns_np.sampling import surface_sample
from sns_np.shapes import Ellipsoid, LinearShape, PerturbedEllipsoid, Sphere
from sns_np.spectral import (
    EigenResult,
    HarmonicField,
    eigenmodes,
    eigenmodes_on_mesh,
    fem_eigenvalues,
    mesh_eigenvalues,
    real_sh,
    richardson,
    sh_index,
)
from sns_np.testing import check_jet

from .conftest import sphere_points

SPHERE_15 = np.repeat([2.0, 6.0, 12.0], [3, 5, 7])


# ------------------------------------------------------------------------------ harmonics

def test_real_harmonics_match_scipy():
    p = sphere_points(40, seed=2)
    theta, phi = np.arccos(p[:, 2]), np.arctan2(p[:, 1], p[:, 0])
    Y = real_sh(p, 12)
    for l in range(13):
        for m in range(-l, l + 1):
            z = sph_harm_y(l, abs(m), theta, phi)  # complex, with the Condon-Shortley phase
            ref = z.real if m == 0 else math.sqrt(2) * (-1) ** m * (z.real if m > 0 else z.imag)
            assert np.allclose(Y[:, sh_index(l, m)], ref, atol=1e-12), (l, m)


def test_harmonic_field_jets_and_solid_extension():
    c = np.random.default_rng(0).standard_normal(49)
    f = HarmonicField(c)
    x = 1.3 * sphere_points(15, seed=3)
    err = check_jet(f, x, order=2, richardson=True)
    assert err["J"] < 1e-8 and err["D2"] < 1e-8
    # solid harmonics are harmonic in R^3 and homogeneous: trace(Hess) = 0, x . grad = l f
    Y, G, H = real_sh(x, 6, 2)
    assert np.abs(np.trace(H, axis1=2, axis2=3)).max() < 1e-10
    l = np.floor(np.sqrt(np.arange(49)))
    assert np.allclose(np.einsum("kjx,kx->kj", G, x), l * Y, atol=1e-10)


# ------------------------------------------------------------------------------ ritz

def test_ritz_unit_sphere_first_15_eigenvalues():
    res = eigenmodes(Sphere(), 15, method="ritz")
    assert isinstance(res, EigenResult) and res.method == "ritz"
    assert np.all(np.abs(res.eigenvalues / SPHERE_15 - 1) < 5e-3)  # the 0.5 %
    assert np.all(np.abs(res.eigenvalues - SPHERE_15) < 1e-9)      # what it actually does
    assert abs(res.constant_eigenvalue) < 1e-10
    assert abs(res.constant_value - 1 / math.sqrt(4 * math.pi)) < 1e-12
    assert res.converged and res.convergence < 1e-6


def residual(S, res, p):
    """max_i |Delta_S phi_i + lambda_i phi_i| / (lambda_i max |phi_i|) at sphere points p."""
    # geometry's chart formula for Delta_S: independent of the Ritz matrices
    return max(np.abs(laplace_beltrami(S, p, f) + lam * f(p)).max() / (lam * np.abs(f(p)).max())
               for lam, f in zip(res.eigenvalues, res.eigenfunctions))


def test_ritz_eigenfunctions_are_orthonormal_eigenfunctions():
    S = PerturbedEllipsoid()
    p = sphere_points(30, seed=5)
    r16 = residual(S, eigenmodes(S, 6, method="ritz", L=16), p)
    res = eigenmodes(S, 6, method="ritz", L=24)
    r24 = residual(S, res, p)
    assert r24 < 2e-5 and r24 < 0.1 * r16  # pointwise, and converging spectrally in L
    s = surface_sample(S, 20000, method="quadrature")
    V = res.evaluate(s.p)
    assert np.allclose(V.T @ (s.weights[:, None] * V), np.eye(6), atol=1e-8)
    assert np.abs(s.weights @ V).max() < 1e-8  # orthogonal to the constants


def test_ritz_ellipsoid_agrees_with_refined_fem():
    S = Ellipsoid(1.0, 1.3, 0.7)
    res = eigenmodes(S, 10, method="ritz")
    fem = {lev: fem_eigenvalues(S, 10, lev) for lev in (3, 4, 5)}
    err = {lev: np.abs(fem[lev] - res.eigenvalues) / res.eigenvalues for lev in fem}
    assert np.all(err[5] < 1e-2)                                     # the 1 %
    # FEM converges to the Ritz values at the rate h^2: errors shrink ~4x per level
    assert np.all(err[4] < 0.35 * err[3]) and np.all(err[5] < 0.35 * err[4])
    assert np.all(fem[5] > res.eigenvalues)  # both are upper bounds; Ritz is the tighter one
    extrapolated = richardson(fem[4], fem[5])
    assert np.all(np.abs(extrapolated / res.eigenvalues - 1) < 2e-4)


@pytest.mark.slow
def test_ritz_ellipsoid_matches_fem_richardson_to_1e6():
    S = Ellipsoid(1.0, 1.3, 0.7)
    res = eigenmodes(S, 10, method="ritz")
    extrapolated = richardson(fem_eigenvalues(S, 10, 5), fem_eigenvalues(S, 10, 6))
    assert np.all(np.abs(extrapolated / res.eigenvalues - 1) < 1e-6)


def test_ritz_convergence_indicator_and_fixed_degree():
    S = Ellipsoid(1.0, 1.3, 0.7)
    coarse = eigenmodes(S, 10, method="ritz", L=6)
    fine = eigenmodes(S, 10, method="ritz", L=12)
    assert coarse.info["L"] == 6 and fine.info["L"] == 12
    # Ritz values decrease monotonically with the degree (nested spaces)
    assert np.all(fine.eigenvalues <= coarse.eigenvalues + 1e-12)
    assert coarse.convergence > 1e-3 and not coarse.converged
    assert fine.convergence < 1e-8 and fine.converged
    true_err = np.abs(coarse.eigenvalues - fine.eigenvalues).max() / fine.eigenvalues.max()
    assert true_err < coarse.convergence  # the indicator is pessimistic, not optimistic
    with pytest.warns(RuntimeWarning, match="did not converge"):
        res = eigenmodes(S, 10, method="ritz", L_max=9, tol=1e-12)
    assert not res.converged


@pytest.mark.slow_nojit
def test_ritz_on_a_fitted_neural_surface_matches_fem_of_its_mesh():
    from sns_np.surface import fit_shape

    S, _ = fit_shape(Ellipsoid(1.0, 1.3, 0.7), width=16, depth=1, steps=60, progress=False,
                     lr=1e-3, normal_weight=1e-4)
    res = eigenmodes(S, 4, method="ritz")
    extrapolated = richardson(fem_eigenvalues(S, 4, 4), fem_eigenvalues(S, 4, 5))
    assert np.all(np.abs(extrapolated / res.eigenvalues - 1) < 1e-3)


def test_eigenmodes_on_mesh_exports_per_vertex_fields():
    from sns_np.mesh import icosphere

    S = Ellipsoid(1.0, 1.3, 0.7)
    res = eigenmodes(S, 3, method="ritz", L=8)
    V, F, fields = eigenmodes_on_mesh(res, S, level=3)
    P, F0 = icosphere(3)
    assert np.array_equal(F, F0) and np.allclose(V, S(P))
    assert set(fields) == {"mode_1", "mode_2", "mode_3", "sphere_x", "sphere_y", "sphere_z"}
    assert np.allclose(fields["mode_2"], res.eigenfunctions[1](P))
    # the per-vertex field is (close to) an FEM eigenvector of the exported mesh
    lam, phi = mesh_eigenvalues(V, F, 3, return_vectors=True)
    u = fields["mode_1"]
    assert abs(abs(u @ phi[:, 0]) / (np.linalg.norm(u) * np.linalg.norm(phi[:, 0])) - 1) < 1e-3


# ------------------------------------------------------------------------------ neural

@pytest.mark.slow_nojit
def test_neural_smoke_shapes_normalisation_and_seed():
    kw = dict(steps=30, n_train=600, batch=256, n_eval=4000)
    res = eigenmodes(Sphere(), 2, method="neural", rng=1, **kw)
    assert res.method == "neural" and res.eigenvalues.shape == (2,)
    assert np.all(np.diff(res.eigenvalues) >= 0) and res.stderr.shape == (2,)
    assert all(isinstance(f, NeuralField) for f in res.eigenfunctions)
    s = surface_sample(Sphere(), 8000, method="quadrature")
    norms = np.sqrt(s.weights @ res.evaluate(s.p) ** 2)
    assert np.all(np.abs(norms - 1) < 0.1)  # unit norm on the (MC) evaluation sample
    again = eigenmodes(Sphere(), 2, method="neural", rng=1, **kw)
    assert np.array_equal(res.eigenvalues, again.eigenvalues)


@pytest.mark.slow_nojit
def test_neural_time_budget_stops_training_and_says_so():
    with pytest.warns(RuntimeWarning, match="time budget"):
        res = eigenmodes(Sphere(), 1, method="neural", steps=100_000, time_budget=0.3,
                         n_train=500, batch=128, n_eval=1000)
    assert not res.converged
    log = res.info["logs"][0]
    assert log["stopped"] == "time_budget" and 0 < log["steps"] < 100_000


@pytest.mark.slow
@pytest.mark.slow_nojit
def test_neural_unit_sphere_first_three_within_3_percent():
    # half the default steps per mode (3000) keeps the test to about 20 s
    res = eigenmodes(Sphere(), 3, method="neural", rng=0, steps=1500)
    assert np.all(np.abs(res.eigenvalues / 2.0 - 1) < 0.03), res.eigenvalues
    assert np.all(res.stderr < 0.01)
    assert res.info["max_inner_product"] < 0.05
    # and the modes are (nearly) in the l = 1 eigenspace: their projection on x, y, z
    s = surface_sample(Sphere(), 8000, method="quadrature")
    V = res.evaluate(s.p)
    Y1 = real_sh(s.p, 1)[:, 1:]
    captured = ((Y1.T @ (s.weights[:, None] * V)) ** 2).sum(axis=0)
    assert np.all(captured > 0.97)


@pytest.mark.slow_nojit
def test_neural_divergence_stops_and_keeps_the_last_good_state(monkeypatch):
    import sns_np.spectral.neural as neural

    real = neural.eigen_loss
    calls = {"n": 0}
    seen = []

    def flaky(field, *args, **kw):
        calls["n"] += 1
        loss, grad = real(field, *args, **kw)
        seen.append(field.theta.copy())
        if calls["n"] == 25:
            grad = grad * np.nan
        return loss, grad

    monkeypatch.setattr(neural, "eigen_loss", flaky)
    with pytest.raises(DivergenceError, match="mode 2") as info:
        eigenmodes(Sphere(), 3, method="neural", steps=20, n_train=500, batch=200,
                   n_eval=2000)
    exc = info.value
    assert exc.partial is not None and exc.partial.k == 1
    assert np.all(np.isfinite(exc.partial.eigenvalues))
    # the diverged field keeps the parameters of the last step with a finite gradient
    assert np.array_equal(exc.field.theta, seen[-2])
    assert np.all(np.isfinite(exc.field.theta))


# ------------------------------------------------------------------------------ bad input

def test_bad_inputs_raise_clear_errors():
    with pytest.raises(ValueError, match="method"):
        eigenmodes(Sphere(), 3, method="arpack")
    with pytest.raises(ValueError, match="k must be"):
        eigenmodes(Sphere(), 0)
    with pytest.raises(ValueError, match=r"cannot be resolved.*L = 2"):
        eigenmodes(Sphere(), 9, method="ritz", L=2)
    with pytest.raises(ValueError, match="L_max"):
        eigenmodes(Sphere(), 5000, method="ritz")
    with pytest.raises(DegenerateMapError, match="degenerate"):
        eigenmodes(LinearShape(np.diag([1.0, 0.0, 0.0])), 3, method="ritz")
    with pytest.raises(DegenerateMapError):
        eigenmodes(LinearShape(np.diag([1.0, 0.0, 0.0])), 1, method="neural", steps=1)
    with pytest.raises(ValueError, match="unknown option"):
        eigenmodes(Sphere(), 1, method="neural", epochs=10)
    with pytest.raises(ValueError, match="lambda_ortho"):
        eigenmodes(Sphere(), 1, method="neural", lambda_ortho=(1.0, -1.0))
    with pytest.raises(ValueError):
        HarmonicField(np.ones(5))
    with pytest.raises(TypeError, match="EigenResult"):
        eigenmodes_on_mesh(np.ones(3), Sphere())
