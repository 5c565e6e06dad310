"""The eigenfunction losses (paper Eqs. 25-27) of a neural scalar field, with their
hand-written parameter gradients.

The losses are evaluated on a :class:`~sns_np.sampling.SurfaceSample`
with weights ``w_i`` (``integral over S of f dA ~= sum w_i f_i``):

    Q     = E / N2,  E = sum w_i G_i^T I_i^-1 G_i,  N2 = sum w_i g_i^2,  G_i = R_i^T grad g(p_i)
    ortho = sum_j c_j^2,   c_j = sum_i w_i g_i phi_j(p_i)      (phi_j unit-norm, fixed)
    reg   = (sqrt(N2) - 1)^2

Their gradients with respect to the network parameters are written by hand: the cotangents of
``g_i`` and ``G_i`` are

    dQ/dG_i = 2 w_i I_i^-1 G_i / N2,                dQ/dg_i = -2 w_i g_i E / N2^2,
    d ortho/dg_i = 2 w_i sum_j c_j phi_j(p_i),      d reg/dg_i = 2 w_i g_i (1 - 1/sqrt(N2)),

and, since ``g`` is the mean of the outputs ``y_o`` and ``G`` the mean of ``J_o R``, they
become the cotangents ``dy = dg / 3`` and ``dJR = dG / 3`` of the network, whose reverse mode
(:meth:`sns_np.nn.ResidualMLP.value_and_grad`, directions ``R``) does the rest. ``R`` and
``I^-1`` belong to the fixed surface and are precomputed once per sample set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import check_positive_float
from ..errors import ShapeError
from ..fields import NeuralField
from ..sampling import SurfaceSample

__all__ = ["EigenLoss", "eigen_loss", "rayleigh_loss", "orthogonality_loss", "unit_norm_loss"]


@dataclass
class EigenLoss:
    """The terms of the eigenfunction loss at one evaluation (all floats).

    Examples
    --------
    >>> from sns_np.sampling import surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(), 200, method="quadrature")
    >>> from sns_np.fields import NeuralField
    >>> loss, _ = eigen_loss(NeuralField(seed=0), s, lambda_ortho=1e3, lambda_reg=1e3)
    >>> sorted(vars(loss)), bool(np.isclose(loss.total,
    ...     loss.rayleigh + 1e3 * loss.ortho + 1e3 * loss.reg))
    (['norm', 'ortho', 'rayleigh', 'reg', 'total'], True)
    """

    total: float
    rayleigh: float
    ortho: float
    reg: float
    norm: float


def _check_previous(previous, n):
    if previous is None:
        return np.zeros((n, 0))
    P = np.asarray(previous, dtype=np.float64)
    if P.ndim == 1:
        P = P[:, None]
    if P.ndim != 2 or P.shape[0] != n:
        raise ShapeError(f"previous must hold the fixed modes' values at the {n} sample points, "
                         f"shape ({n}, k); got {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ShapeError("previous contains non-finite values")
    return P


def _terms(g, G, sample, P, w_q, w_o, w_r):
    """Loss and cotangents (dg (n,), dG (n, 2)) from field values g and tangent gradients G."""
    w = sample.weights
    IG = np.einsum("kab,kb->ka", sample.Iinv, G)
    E = float(w @ np.einsum("ka,ka->k", G, IG))
    N2 = float(w @ (g * g))
    if not N2 > 0.0:
        raise ValueError("the field vanishes on the sample (||h||^2 = 0): the Rayleigh quotient "
                         "is undefined")
    norm = np.sqrt(N2)
    Q = E / N2
    c = (w * g) @ P
    ortho = float(c @ c)
    reg = (norm - 1.0) ** 2
    dG = (2.0 * w_q / N2) * w[:, None] * IG
    dg = w * (-2.0 * w_q * E / N2 ** 2 * g + 2.0 * w_o * (P @ c)
              + 2.0 * w_r * (1.0 - 1.0 / norm) * g)
    total = w_q * Q + w_o * ortho + w_r * reg
    return EigenLoss(total, Q, ortho, reg, norm), dg, dG


def eigen_loss(field: NeuralField, sample: SurfaceSample, previous=None,
               lambda_ortho: float = 0.0, lambda_reg: float = 0.0, *, rayleigh: float = 1.0):
    """``rayleigh * Q + lambda_ortho * ortho + lambda_reg * reg`` and its parameter gradient.

    The eigenfunction loss of paper Eq. 27 (see the module notes for the terms).

    Parameters
    ----------
    field : NeuralField
    sample : SurfaceSample (points, weights, ``R``, ``I^-1`` of the fixed surface)
    previous : (n, k) float array, optional
        Values at ``sample.p`` of the fixed, unit-norm modes that ``h`` must be orthogonal
        to (include the constant ``1 / sqrt(area)`` for ``<h, 1>``).
    lambda_ortho, lambda_reg : float >= 0
    rayleigh : float >= 0, weight of the Rayleigh quotient

    Returns
    -------
    loss : EigenLoss
    grad : (n_params,) float array, d total / d theta

    Examples
    --------
    >>> from sns_np.sampling import surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(), 256, rng=0)
    >>> from sns_np.fields import NeuralField
    >>> loss, grad = eigen_loss(NeuralField(seed=1), s, lambda_reg=1.0)
    >>> grad.shape, loss.rayleigh > 0
    ((460,), True)
    """
    if not isinstance(field, NeuralField):
        raise TypeError(f"field must be a NeuralField, got {type(field).__name__}")
    if not isinstance(sample, SurfaceSample):
        raise TypeError(f"sample must be a SurfaceSample, got {type(sample).__name__}")
    w_q = check_positive_float(rayleigh, "rayleigh", allow_zero=True)
    w_o = check_positive_float(lambda_ortho, "lambda_ortho", allow_zero=True)
    w_r = check_positive_float(lambda_reg, "lambda_reg", allow_zero=True)
    n = len(sample)
    P = _check_previous(previous, n)
    net = field.net
    c = field.scale / net.out_dim
    result = {}

    def loss_fn(y, JR, sl):
        if sl.start != 0 or sl.stop != n:  # the loss couples all points
            raise RuntimeError("eigen_loss needs the whole sample in one call")
        g = c * y.sum(axis=1)
        G = c * JR.sum(axis=1)
        loss, dg, dG = _terms(g, G, sample, P, w_q, w_o, w_r)
        result["loss"] = loss
        dy = np.repeat((c * dg)[:, None], net.out_dim, axis=1)
        dJR = np.repeat((c * dG)[:, None, :], net.out_dim, axis=1)
        return loss.total, dy, dJR

    if net.single_pass:  # one fused Numba pass over all points
        _, grad = net.value_and_grad(sample.p, loss_fn, order=1, directions=sample.R)
    else:  # the BLAS path chunks the points: forward first, then the reverse pass
        y, JR = net.jet(sample.p, 1, directions=sample.R)
        _, dy, dJR = loss_fn(y, JR, slice(0, n))
        grad = net.vjp(sample.p, dy, dJR, directions=sample.R)
    return result["loss"], np.asarray(grad, dtype=np.float64)


def rayleigh_loss(field: NeuralField, sample: SurfaceSample):
    """``Q(h) = ||grad_S h||^2 / ||h||^2`` on the sample (paper Eq. 20) and its gradient.

    Returns
    -------
    (float, (n_params,) float array)

    Examples
    --------
    >>> from sns_np.sampling import rayleigh_quotient, surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(), 800, method="quadrature")
    >>> from sns_np.fields import NeuralField
    >>> f = NeuralField(seed=0)
    >>> q, grad = rayleigh_loss(f, s)
    >>> bool(np.isclose(q, rayleigh_quotient(Sphere(), f, 800, method="quadrature").value))
    True
    >>> grad.shape
    (460,)
    """
    loss, grad = eigen_loss(field, sample)
    return loss.rayleigh, grad


def orthogonality_loss(field: NeuralField, sample: SurfaceSample, previous):
    """``sum_j <h, phi_j>^2`` (paper Eq. 25) and its gradient; ``previous`` (n, k) as in
    :func:`eigen_loss`.

    Examples
    --------
    >>> from sns_np.sampling import surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(), 800, method="quadrature")
    >>> constant = np.full((len(s), 1), 1 / np.sqrt(4 * np.pi))   # the unit-norm constant mode
    >>> from sns_np.fields import NeuralField
    >>> value, grad = orthogonality_loss(NeuralField(seed=0), s, constant)
    >>> value >= 0, grad.shape
    (True, (460,))
    """
    loss, grad = eigen_loss(field, sample, previous, lambda_ortho=1.0, rayleigh=0.0)
    return loss.ortho, grad


def unit_norm_loss(field: NeuralField, sample: SurfaceSample):
    """``(||h|| - 1)^2`` (paper Eq. 26) and its gradient.

    Examples
    --------
    >>> from sns_np.sampling import surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(), 800, method="quadrature")
    >>> from sns_np.fields import NeuralField
    >>> f = NeuralField(seed=0)
    >>> norm = np.sqrt(s.integral(f(s.p) ** 2).value)
    >>> value, grad = unit_norm_loss(f, s)
    >>> bool(np.isclose(value, (norm - 1) ** 2))
    True
    """
    loss, grad = eigen_loss(field, sample, lambda_reg=1.0, rayleigh=0.0)
    return loss.reg, grad
