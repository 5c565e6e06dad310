"""Neural scalar fields on the sphere.

A :class:`NeuralField` is the reference's scalar-field network (paper Sec. 6, implementation
details: a residual softplus MLP ``R^3 -> R^3`` of width 10 with 2 residual blocks, the scalar
being the mean of the 3 outputs), evaluated at sphere points. It follows the field protocol
of DESIGN.md, with ambient value, gradient and Hessian; the surface field is
``h(S(p)) = g(p)`` (paper Eq. 23).

The eigenfunction losses that train such fields live in :mod:`sns_np.spectral.losses`.
"""

from __future__ import annotations

import numpy as np

from . import _npz
from ._npz import load_npz, save_npz
from ._validation import as_points, check_order, check_positive_int
from .errors import ModelFileError
from .nn.mlp import ResidualMLP

__all__ = ["NeuralField"]

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
