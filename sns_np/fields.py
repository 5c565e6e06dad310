"""Neural scalar fields on the sphere and the eigenfunction losses with their parameter gradients.

A :class:`NeuralField` is the reference's scalar-field network (paper Sec. 6, implementation
details: a residual softplus MLP ``R^3 -> R^3`` of width 10 with 2 residual blocks, the scalar
being the mean of the 3 outputs), evaluated at sphere points. It follows the field protocol
of DESIGN.md, with ambient value, gradient and Hessian; the surface field is
``h(S(p)) = g(p)`` (paper Eq. 23).

The eigenfunction losses (paper Eqs. 25-27) on a :class:`~sns_np.sampling.SurfaceSample`
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

from . import _npz
from ._npz import load_npz, save_npz
from ._validation import as_points, check_order, check_positive_float, check_positive_int
from .errors import ModelFileError, ShapeError
from .nn.mlp import SMALL_WIDTH, ResidualMLP
from .sampling import SurfaceSample

__all__ = ["NeuralField", "EigenLoss", "eigen_loss", "rayleigh_loss", "orthogonality_loss",
           "unit_norm_loss"]

FORMAT = "sns_np.NeuralField"
FORMAT_VERSION = 1


class NeuralField:
    """A scalar field ``g(x) = scale * mean_o net(x)_o`` given by a small residual MLP.

    Parameters
    ----------
    width : int, hidden width (10 in the paper)
    depth : int, residual blocks (2 in the paper)
    n_outputs : int, outputs averaged into the scalar (3 in the paper)
    bias : bool, layers with biases (the reference has none)
    seed : None, int or numpy.random.Generator, initialisation
    scale : float, a fixed output factor (eigenmodes use it to store the unit-norm scaling)
    net : ResidualMLP, optional, wrap an existing network (``width``, ``depth``,
        ``n_outputs``, ``bias`` and ``seed`` are then ignored)

    Examples
    --------
    >>> f = NeuralField(seed=0)
    >>> v, g, H = f.jet(np.array([[0.0, 0.0, 1.0]]), 2)
    >>> v.shape, g.shape, H.shape, f.n_params
    ((1,), (1, 3), (1, 3, 3), 460)
    """

    def __init__(self, width: int = 10, depth: int = 2, n_outputs: int = 3, bias: bool = False,
                 seed=None, scale: float = 1.0, net: ResidualMLP | None = None):
        if net is None:
            net = ResidualMLP(3, check_positive_int(n_outputs, "n_outputs"), width=width,
                              depth=depth, bias=bias, seed=seed)
        if not isinstance(net, ResidualMLP) or net.in_dim != 3:
            raise ValueError(f"net must be a ResidualMLP with in_dim 3, got {net!r}")
        if net.dtype != np.float64:
            net = net.astype(np.float64)
        scale = float(scale)
        if not np.isfinite(scale) or scale == 0.0:
            raise ValueError(f"scale must be finite and non-zero, got {scale}")
        self.net, self.scale = net, scale

    # -------------------------------------------------------------- field protocol
    def jet(self, x, order: int = 0):
        """Value (n,), gradient (n, 3) and Hessian (n, 3, 3) at ``x`` (n, 3), ambient in R^3.

        Examples
        --------
        >>> from sns_np.testing import check_jet
        >>> f = NeuralField(seed=0)
        >>> p = np.array([[0.0, 0.6, 0.8]])
        >>> v, g, H = f.jet(p, order=2)
        >>> bool(np.allclose(v, f.net(p).mean(axis=1)))          # the mean of the 3 outputs
        True
        >>> bool(max(check_jet(f, p).values()) < 1e-6)
        True
        """
        order = check_order(order)
        x = as_points(x, "x")
        c = self.scale / self.net.out_dim
        out = self.net.jet(x, order)
        if order == 0:
            return c * out.sum(axis=1)
        return tuple(c * a.sum(axis=1) for a in out)

    def __call__(self, x) -> np.ndarray:
        """The value at ``x`` (n, 3), (n,).

        Examples
        --------
        >>> f = NeuralField(seed=0, scale=2.0)
        >>> p = np.array([[1.0, 0.0, 0.0]])
        >>> bool(np.allclose(f(p), 2.0 * f.net(p).mean(axis=1))), f.value(p).shape
        (True, (1,))
        """
        return self.jet(x, 0)

    value = __call__

    # -------------------------------------------------------------- parameters
    @property
    def theta(self) -> np.ndarray:
        """The live parameter vector of the network (n_params,)."""
        return self.net.theta

    @property
    def n_params(self) -> int:
        return self.net.n_params

    def copy(self) -> NeuralField:
        """An independent field with the same network parameters and scale.

        Examples
        --------
        >>> f = NeuralField(seed=0)
        >>> g = f.copy()
        >>> g.theta[:] = 0.0
        >>> float(abs(f.theta).max()) > 0                        # f keeps its parameters
        True
        """
        return NeuralField(net=self.net.copy(), scale=self.scale)

    def __repr__(self):
        return (f"NeuralField(width={self.net.width}, depth={self.net.depth}, "
                f"n_outputs={self.net.out_dim}, scale={self.scale:.6g})")

    # -------------------------------------------------------------- files
    def state(self, prefix: str = "") -> dict:
        """The arrays that describe the field (format, scale and its network's
        :meth:`ResidualMLP.state` under ``net.``).

        Examples
        --------
        >>> f = NeuralField(width=4, depth=1, seed=0)
        >>> state = f.state()
        >>> str(state["format"]), bool(np.array_equal(state["net.theta"], f.theta))
        ('sns_np.NeuralField', True)
        """
        out = {f"{prefix}format": np.array(FORMAT),
               f"{prefix}format_version": np.array(FORMAT_VERSION),
               f"{prefix}scale": np.array(self.scale)}
        out.update(self.net.state(prefix=f"{prefix}net."))
        return out

    @classmethod
    def from_state(cls, data, prefix: str = "", source: str = "state") -> NeuralField:
        """Rebuild a field from :meth:`state` arrays (or an open file), checking every field; any
        problem is a :class:`ModelFileError` naming ``source``.

        Examples
        --------
        >>> f = NeuralField(width=4, depth=1, seed=0, scale=0.5)
        >>> g = NeuralField.from_state(f.state())
        >>> g.scale, bool(np.array_equal(g.theta, f.theta))
        (0.5, True)
        """
        key = f"{prefix}format"
        found = (_npz.field(data, key, source, kinds="U", what="text") if key in data
                 else "nothing")
        if found != FORMAT:
            raise ModelFileError(f"{source}: expected a {FORMAT} (field {key!r}), found "
                                 f"{found[:80]!r}")
        version = _npz.int_field(data, f"{prefix}format_version", source)
        if version != FORMAT_VERSION:
            raise ModelFileError(f"{source}: field format version {version} is not supported")
        scale = _npz.field(data, f"{prefix}scale", source, kinds="fiu", what="a number")
        net = ResidualMLP.from_state(data, prefix=f"{prefix}net.", source=source)
        try:
            return cls(net=net, scale=float(scale))
        except ValueError as exc:
            raise ModelFileError(f"{source}: invalid field ({exc})") from None

    def save(self, path):
        """Write the field to ``path`` (.npz, no pickles), atomically.

        Examples
        --------
        >>> NeuralField(seed=0).save("mode.npz").name
        'mode.npz'
        """
        return save_npz(path, self.state())

    @classmethod
    def load(cls, path) -> NeuralField:
        """Read a field written by :meth:`save`.

        Examples
        --------
        >>> path = NeuralField(width=4, depth=1, seed=0).save("mode.npz")
        >>> NeuralField.load(path)
        NeuralField(width=4, depth=1, n_outputs=3, scale=1)
        """
        try:
            with load_npz(path) as data:
                return cls.from_state(data, source=str(path))
        except (RecursionError, MemoryError) as exc:   # a last line of defence: one line
            raise ModelFileError(f"{path}: cannot be read ({type(exc).__name__})") from None


# ------------------------------------------------------------------------------ losses

@dataclass
class EigenLoss:
    """The terms of the eigenfunction loss at one evaluation (all floats).

    Examples
    --------
    >>> from sns_np.sampling import surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(), 200, method="quadrature")
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

    if net.width <= SMALL_WIDTH:  # one fused Numba pass over all points
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
    >>> f = NeuralField(seed=0)
    >>> norm = np.sqrt(s.integral(f(s.p) ** 2).value)
    >>> value, grad = unit_norm_loss(f, s)
    >>> bool(np.isclose(value, (norm - 1) ** 2))
    True
    """
    loss, grad = eigen_loss(field, sample, lambda_reg=1.0, rayleigh=0.0)
    return loss.reg, grad
