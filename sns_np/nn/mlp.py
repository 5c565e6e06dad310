"""The residual softplus MLP with hand-written forward jets and reverse-mode gradients.

Architecture (the reference implementation's, DESIGN.md)::

    h = s(W0 x + b0)
    h = s(h + W2_k s(W1_k h + b1_k) + b2_k)      k = 0 .. depth-1
    y = W3 h + b3

with s = softplus (beta = 1) and biases optional (the reference has none). For width 256,
depth 8, no biases: 1,050,112 parameters.

Forward mode (``jet``) propagates the value, first derivatives along m directions and second
derivatives along pairs of the first k of them as *streams* stacked in one array, so that every
linear layer is one matrix product over all streams and every activation one fused Numba pass
(see ``docs/engine.md`` for the derivation, line by line).

Reverse mode (``vjp``, ``value_and_grad``) differentiates a loss that depends on the value and
the first derivatives (position and normal losses, Rayleigh quotients) with respect to all
parameters, by running the first-order forward-mode computation backwards.

All parameters live in one flat vector ``theta``; the weight matrices are views into it, so
``pack``/``unpack`` connect directly to ``scipy.optimize`` and the optimisers of
:mod:`sns_np.nn.optim`.
"""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np

from .. import _npz
from .._atomic import write_file
from .._npz import load_npz
from .._validation import (
    as_float_array,
    as_generator,
    check_finite,
    check_order,
    check_positive_float,
    check_positive_int,
)
from ..errors import ModelFileError, ShapeError
from . import _kernels as K
from . import _parallel

__all__ = ["ResidualMLP", "n_streams", "load_npz", "save_npz"]

FORMAT = "sns_np.ResidualMLP"
FORMAT_VERSION = 1

#: widths up to this use the per-point Numba kernels instead of BLAS
SMALL_WIDTH = 32

#: rows (points x streams) per chunk on the BLAS path: 2 MB per activation buffer at width 256
#: in float64. Measured for the full jet and the training step with one worker per core
#: (docs/performance.md): 512 to 1536 rows are within noise, 4096 rows lose 10-20%.
_ROWS_PER_CHUNK = {np.dtype(np.float64): 1024, np.dtype(np.float32): 1024}


def n_streams(m: int, k: int) -> int:
    """Number of streams: the value, m first-order and k (k + 1) / 2 second-order ones.

    Examples
    --------
    >>> n_streams(3, 0), n_streams(3, 3), n_streams(3, 2)         # value+J, +D2, geometry's 7
    (4, 10, 7)
    """
    return 1 + m + k * (k + 1) // 2


def _pairs(k):
    return [(a, b) for a in range(k) for b in range(a, k)]


class ResidualMLP:
    """Residual softplus MLP ``R^in_dim -> R^out_dim`` with exact jets and gradients.

    Parameters
    ----------
    in_dim, out_dim : int
        Input and output dimensions (3 and 3 for a surface map).
    width : int
        Hidden width (256 in the reference surface network, 10 for scalar fields).
    depth : int
        Number of residual blocks (8, resp. 2).
    bias : bool
        Whether the layers have biases (the reference has none).
    seed : None, int or numpy.random.Generator
        Seed of the initialisation (``None`` means seed 0: reproducible by default).
    dtype : numpy float dtype
        ``np.float64`` (default) or ``np.float32``: parameters, activations and outputs.
    chunk_size : int, optional
        Most points per chunk in ``jet``/``vjp`` (default: chosen from the number of streams so
        that activations stay cache-sized). Bounds memory on any input size. Chunks are
        shrunk so that the worker threads get equal shares (see docs/performance.md).
    input_scale : float
        Scale of the first layer's initial weights (see Notes); only the initialisation uses it.

    Notes
    -----
    Initialisation (normal, zero mean; ``fan_in`` of the layer):

    * ``W0``: std ``input_scale / sqrt(in_dim)``, ``input_scale`` = 2 by default. On
      unit-sphere inputs the pre-activations then have std about 1.15, so the softplus
      features are genuinely non-linear over the sphere (PyTorch's default, std
      ``1 / sqrt(3 in_dim)``, leaves them nearly linear). Surface fitting uses 4 (features
      that vary on a fraction of the sphere; measured in docs/fitting.md).
    * ``W1_k``: std ``sqrt(2 / width)`` (He), keeping the inner branch's scale.
    * ``W2_k``: std ``1 / sqrt(width * depth)``, so the residual branches add up to O(1)
      over all blocks and the depth does not inflate the signal.
    * ``W3``: std ``1e-2 / sqrt(width)``: the map starts near a point, like the reference
      (whose last layer is the constant 1e-4), but with random directions. Fitting
      (:mod:`sns_np.surface`) replaces it by a least-squares fit of the initial features.
    * biases: zero.

    Examples
    --------
    >>> net = ResidualMLP(width=16, depth=2, seed=0)
    >>> y, J = net.jet(np.array([[0.0, 0.0, 1.0]]), order=1)
    >>> y.shape, J.shape
    ((1, 3), (1, 3, 3))
    """

    def __init__(self, in_dim=3, out_dim=3, width=256, depth=8, bias=False, seed=None,
                 dtype=np.float64, chunk_size=None, input_scale=2.0):
        self._setup(in_dim, out_dim, width, depth, bias, dtype, chunk_size, input_scale)
        self.initialize(seed)

    def _setup(self, in_dim, out_dim, width, depth, bias, dtype, chunk_size, input_scale):
        """Check the architecture and allocate zero parameters (no random draw)."""
        self.in_dim = check_positive_int(in_dim, "in_dim")
        self.out_dim = check_positive_int(out_dim, "out_dim")
        self.width = check_positive_int(width, "width")
        self.depth = check_positive_int(depth, "depth", minimum=0)
        if not isinstance(bias, (bool, np.bool_)):
            raise ValueError(f"bias must be True or False, got {bias!r}")
        self.bias = bool(bias)
        dt = np.dtype(dtype)
        if dt not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise ValueError(f"dtype must be float32 or float64, got {dt}")
        self.dtype = dt
        self.chunk_size = None if chunk_size is None else check_positive_int(chunk_size,
                                                                              "chunk_size")
        self.input_scale = check_positive_float(input_scale, "input_scale")
        self._build_layout()
        self._theta = np.zeros(self.n_params, dtype=self.dtype)
        self._bind_views(self._theta)

    @classmethod
    def zeros(cls, in_dim=3, out_dim=3, width=256, depth=8, bias=False, dtype=np.float64,
              chunk_size=None) -> ResidualMLP:
        """A network of the given architecture with all parameters zero (nothing drawn).

        The way to build a network whose parameters come from elsewhere (a file, another
        network): fill it with :meth:`unpack` or through :attr:`theta`.

        Examples
        --------
        >>> net = ResidualMLP.zeros(width=4, depth=1)
        >>> net.n_params, float(abs(net.theta).max())
        (56, 0.0)
        """
        net = cls.__new__(cls)
        net._setup(in_dim, out_dim, width, depth, bias, dtype, chunk_size, 2.0)
        return net

    @staticmethod
    def count_params(in_dim, out_dim, width, depth, bias=False) -> int:
        """Number of parameters of an architecture, in exact integer arithmetic.

        ``w d + 2 L w^2 + o w`` plus ``w + 2 L w + o`` biases (d = in_dim, o = out_dim,
        w = width, L = depth); for the reference network (3, 3, 256, 8): 1,050,112.

        Examples
        --------
        >>> ResidualMLP.count_params(3, 3, 256, 8)       # the reference surface network
        1050112
        >>> ResidualMLP.count_params(3, 3, 10, 2, bias=True)
        513
        """
        d, o, w, L = (int(v) for v in (in_dim, out_dim, width, depth))
        n = w * d + 2 * L * w * w + o * w
        return n + (w + 2 * L * w + o if bias else 0)

    # ------------------------------------------------------------------ parameters
    def _build_layout(self):
        d, w, o, L = self.in_dim, self.width, self.out_dim, self.depth
        nb = 1 if self.bias else 0
        self._shapes = {
            "W0": (w, d), "b0": (w * nb,),
            "W1": (L, w, w), "b1": (L, w * nb),
            "W2": (L, w, w), "b2": (L, w * nb),
            "W3": (o, w), "b3": (o * nb,),
        }
        self._offsets = {}
        off = 0
        for name, shape in self._shapes.items():
            size = int(np.prod(shape))
            self._offsets[name] = (off, off + size)
            off += size
        self.n_params = off

    def _bind_views(self, buf):
        for name, shape in self._shapes.items():
            lo, hi = self._offsets[name]
            setattr(self, name, buf[lo:hi].reshape(shape))

    def param_slices(self) -> dict:
        """Name -> (slice into theta, shape) for every parameter array.

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> sl, shape = net.param_slices()["W1"]
        >>> shape, net.pack()[sl].reshape(shape).shape
        ((1, 4, 4), (1, 4, 4))
        """
        return {name: (slice(*self._offsets[name]), self._shapes[name]) for name in self._shapes}

    def initialize(self, seed=None):
        """Draw fresh parameters (see the class Notes for the scheme).

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> theta = net.pack()
        >>> bool(np.array_equal(net.initialize(seed=0).pack(), theta))   # same seed, same draw
        True
        >>> bool(np.array_equal(net.initialize(seed=1).pack(), theta))
        False
        """
        g = as_generator(seed)
        w, d, L = self.width, self.in_dim, self.depth
        self.W0[...] = g.standard_normal(self.W0.shape) * (self.input_scale / np.sqrt(d))
        self.W1[...] = g.standard_normal(self.W1.shape) * np.sqrt(2.0 / w)
        self.W2[...] = g.standard_normal(self.W2.shape) / np.sqrt(w * max(L, 1))
        self.W3[...] = g.standard_normal(self.W3.shape) * (1e-2 / np.sqrt(w))
        for b in ("b0", "b1", "b2", "b3"):
            getattr(self, b)[...] = 0.0
        return self

    def pack(self) -> np.ndarray:
        """A copy of all parameters as one flat vector (n_params,) in the network's dtype.

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> theta = net.pack()
        >>> theta.shape == (net.n_params,), theta is net.theta      # a copy, not the live buffer
        (True, False)
        """
        return self._theta.copy()

    def unpack(self, theta) -> ResidualMLP:
        """Set all parameters from a flat vector (n_params,) (rounded to the network's dtype).

        The weight arrays (``W0``, ``W1``, ...) stay views of one internal buffer, so existing
        references to them see the new values.

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> net.unpack(np.zeros(net.n_params))(np.ones((2, 3)))   # all-zero parameters: y = 0
        array([[0., 0., 0.],
               [0., 0., 0.]])
        """
        arr = np.asarray(theta)
        if arr.dtype == object or np.iscomplexobj(arr) or not (
                np.issubdtype(arr.dtype, np.floating)):
            raise ShapeError(f"theta must be a real floating vector, got dtype {arr.dtype}")
        if arr.shape != (self.n_params,):
            raise ShapeError(f"theta must have shape ({self.n_params},) for this network, got "
                             f"{arr.shape}")
        check_finite(arr, "theta")
        self._theta[...] = arr
        return self

    @property
    def theta(self) -> np.ndarray:
        """The live parameter buffer (n_params,); writing to it changes the network."""
        return self._theta

    @property
    def single_pass(self) -> bool:
        """True when the network runs on the per-point Numba kernels (width <= SMALL_WIDTH):
        :meth:`value_and_grad` then calls its ``loss_fn`` once, with all the points."""
        return self.width <= SMALL_WIDTH

    def copy(self) -> ResidualMLP:
        """An independent network with the same architecture and parameters.

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> twin = net.copy()
        >>> twin.theta[:] = 0.0
        >>> bool(np.any(net.theta != 0.0))                            # the original is untouched
        True
        """
        new = ResidualMLP.zeros(self.in_dim, self.out_dim, self.width, self.depth, self.bias,
                                dtype=self.dtype, chunk_size=self.chunk_size)
        new._theta[...] = self._theta
        new.input_scale = self.input_scale
        return new

    def astype(self, dtype) -> ResidualMLP:
        """The same network with parameters converted to ``dtype``.

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0).astype(np.float32)
        >>> net.dtype, net(np.ones((1, 3), np.float32)).dtype
        (dtype('float32'), dtype('float32'))
        """
        new = ResidualMLP.zeros(self.in_dim, self.out_dim, self.width, self.depth, self.bias,
                                dtype=dtype, chunk_size=self.chunk_size)
        new.unpack(self._theta.astype(dtype))
        new.input_scale = self.input_scale
        return new

    def architecture(self) -> dict:
        """The architecture as a dict: ``in_dim``, ``out_dim``, ``width``, ``depth``, ``bias``.

        Examples
        --------
        >>> ResidualMLP(width=16, depth=2).architecture()
        {'in_dim': 3, 'out_dim': 3, 'width': 16, 'depth': 2, 'bias': False}
        """
        return dict(in_dim=self.in_dim, out_dim=self.out_dim, width=self.width,
                    depth=self.depth, bias=self.bias)

    def __repr__(self):
        a = self.architecture()
        return (f"ResidualMLP(in_dim={a['in_dim']}, out_dim={a['out_dim']}, width={a['width']}, "
                f"depth={a['depth']}, bias={a['bias']}, dtype={self.dtype.name}; "
                f"{self.n_params:,} parameters)")

    # ------------------------------------------------------------------ save / load
    def state(self, prefix: str = "") -> dict:
        """The arrays that describe this network (architecture, dtype, format, parameters).

        Examples
        --------
        >>> state = ResidualMLP(width=4, depth=1, seed=0).state()
        >>> sorted(state)
        ['bias', 'depth', 'dtype', 'format', 'format_version', 'in_dim', 'out_dim', 'theta',
         'width']
        >>> ResidualMLP.from_state(state).width
        4
        """
        a = self.architecture()
        return {
            f"{prefix}format": np.array(FORMAT),
            f"{prefix}format_version": np.array(FORMAT_VERSION),
            f"{prefix}in_dim": np.array(a["in_dim"]), f"{prefix}out_dim": np.array(a["out_dim"]),
            f"{prefix}width": np.array(a["width"]), f"{prefix}depth": np.array(a["depth"]),
            f"{prefix}bias": np.array(a["bias"]), f"{prefix}dtype": np.array(self.dtype.name),
            f"{prefix}theta": self._theta,
        }

    @classmethod
    def from_state(cls, data, prefix: str = "", source: str = "state") -> ResidualMLP:
        """Rebuild a network from :meth:`state` arrays, checking every field.

        ``data`` is a dict of arrays or an open file (:func:`load_npz`). The parameter count
        implied by the architecture fields is compared with the declared shape of ``theta``
        before anything of that size is allocated, and the parameters are read straight into
        the new network's buffer (no random initialisation is drawn).

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> again = ResidualMLP.from_state(net.state())
        >>> bool(np.array_equal(again.pack(), net.pack()))
        True
        """
        if prefix + "format" not in data:
            raise ModelFileError(f"{source}: missing field {prefix + 'format'!r}; not a "
                                 f"{FORMAT} file")
        fmt = _npz.field(data, prefix + "format", source, kinds="U", what="text")
        if fmt != FORMAT:
            raise ModelFileError(f"{source}: format is {fmt!r}, expected {FORMAT!r}")
        version = _npz.int_field(data, prefix + "format_version", source)
        if version != FORMAT_VERSION:
            raise ModelFileError(f"{source}: format version {version} is not supported "
                                 f"(this sns_np reads version {FORMAT_VERSION})")
        arch = {k: _npz.int_field(data, prefix + k, source, minimum=0 if k == "depth" else 1)
                for k in ("in_dim", "out_dim", "width", "depth")}
        bias = _npz.field(data, prefix + "bias", source, kinds="b", what="True or False")
        name = _npz.field(data, prefix + "dtype", source, kinds="U", what="a dtype name")
        if name not in ("float32", "float64"):
            raise ModelFileError(f"{source}: field {prefix + 'dtype'!r} must be 'float32' or "
                                 f"'float64', got {name[:40]!r}")
        dtype = np.dtype(name)
        n = cls.count_params(**arch, bias=bias)
        key = prefix + "theta"
        if key not in data:
            raise ModelFileError(f"{source}: missing field {key!r}")
        shape, dt = _npz.declared(data, key)
        if shape != (n,) or dt != dtype:
            raise ModelFileError(
                f"{source}: field {key!r} (the parameter vector) has shape {shape} and dtype "
                f"{dt}; the stored architecture ({arch['width']} wide, {arch['depth']} blocks) "
                f"needs ({n},) {dtype}")
        net = cls.zeros(**arch, bias=bias, dtype=dtype)
        if isinstance(data, _npz.NpzReader):
            data.read_into(key, net._theta)
        else:
            net._theta[...] = data[key]
        if not np.all(np.isfinite(net._theta)):
            raise ModelFileError(f"{source}: field {key!r} contains non-finite values")
        return net

    def save(self, path) -> Path:
        """Write the network to ``path`` (.npz, no pickles), atomically (temp file + rename).

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> net.save("net.npz").name
        'net.npz'
        >>> bool(np.array_equal(ResidualMLP.load("net.npz").pack(), net.pack()))
        True
        """
        return save_npz(path, self.state())

    @classmethod
    def load(cls, path) -> ResidualMLP:
        """Read a network written by :meth:`save`; never unpickles (sizes are checked before
        anything is allocated: sns_np/_npz.py).

        Examples
        --------
        >>> path = ResidualMLP(width=4, depth=1, seed=0).save("net.npz")
        >>> ResidualMLP.load(path)
        ResidualMLP(in_dim=3, out_dim=3, width=4, depth=1, bias=False, dtype=float64; 56 parameters)
        """
        try:
            with load_npz(path) as data:
                return cls.from_state(data, source=str(path))
        except (RecursionError, MemoryError) as exc:   # a last line of defence: one line
            raise ModelFileError(f"{path}: cannot be read ({type(exc).__name__})") from None

    # ------------------------------------------------------------------ forward jets
    def _check_x(self, x):
        x = as_float_array(x, "x")
        if x.ndim != 2 or x.shape[1] != self.in_dim:
            raise ShapeError(f"x must have shape (n, {self.in_dim}), got {x.shape}")
        check_finite(x, "x")
        return x.astype(self.dtype, copy=False)

    def _check_directions(self, D, n):
        D = as_float_array(D, "directions")
        if D.ndim != 3 or D.shape[0] != n or D.shape[1] != self.in_dim or D.shape[2] < 1:
            raise ShapeError(f"directions must have shape ({n}, {self.in_dim}, m) with m >= 1, "
                             f"got {D.shape}")
        check_finite(D, "directions")
        return np.ascontiguousarray(D, dtype=self.dtype)

    def _chunk(self, S):
        if self.chunk_size is not None:
            return self.chunk_size
        return max(16, _ROWS_PER_CHUNK[self.dtype] // S)

    def jet(self, x, order=0, directions=None, second=None):
        """Value and derivatives of the network at ``x``.

        Parameters
        ----------
        x : (n, in_dim) float array
        order : int, 0, 1 or 2
        directions : (n, in_dim, m) float array, optional
            Per-point directions. Without them the full Jacobian and Hessian are returned.
        second : int, optional
            With ``directions`` and order 2: second derivatives along the pairs of the first
            ``second`` columns only (default all m). Geometry passes [e_u, e_v, p] with
            ``second=2``: 7 streams instead of the 10 of a full Hessian.

        Returns
        -------
        order 0: y (n, out_dim)
        order 1: (y, J) with J (n, out_dim, in_dim), ``J[k, i, a] = dy_i / dx_a``;
                 with directions, JD (n, out_dim, m) = J @ D
        order 2: (y, J, D2) with D2 (n, out_dim, in_dim, in_dim); with directions
                 D2D (n, out_dim, k, k), ``D2D[., i, a, b] = D2_i(d_a, d_b)``

        Examples
        --------
        >>> net = ResidualMLP(width=16, depth=2, seed=0)
        >>> x = np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])
        >>> y, J, D2 = net.jet(x, order=2)
        >>> y.shape, J.shape, D2.shape
        ((2, 3), (2, 3, 3), (2, 3, 3, 3))
        >>> bool(np.allclose(D2, np.swapaxes(D2, 2, 3)))              # Hessians are symmetric
        True
        >>> JD, = net.jet(x, order=1, directions=np.eye(3)[None, :, :2].repeat(2, 0))[1:]
        >>> bool(np.allclose(JD, J[:, :, :2]))                        # J along two directions
        True
        """
        order = check_order(order)
        x = self._check_x(x)
        n = x.shape[0]
        d = self.in_dim
        if directions is None:
            if second is not None:
                raise ValueError("second= needs directions=")
            m = d if order >= 1 else 0
            k = d if order == 2 else 0
            D = None
        else:
            if order == 0:
                raise ValueError("directions= needs order 1 or 2")
            D = self._check_directions(directions, n)
            m = D.shape[2]
            if second is None:
                k = m if order == 2 else 0
            else:
                if order != 2:
                    raise ValueError("second= needs order=2")
                if isinstance(second, bool) or not isinstance(second, (int, np.integer)) or \
                        not 0 <= second <= m:
                    raise ValueError(f"second must be an integer in [0, {m}], got {second!r}")
                k = int(second)
        S = n_streams(m, k)
        Y = np.empty((n, S, self.out_dim), dtype=self.dtype)
        if n:
            if self.width <= SMALL_WIDTH:
                self._forward_small(x, D, m, k, Y)
            else:
                self._forward_blas(x, D, m, k, Y)
        return _unpack_streams(Y, order, m, k)

    def __call__(self, x):
        """The value y (n, out_dim) at x (n, in_dim)."""
        return self.jet(x, 0)

    def features(self, x, chunk_size=65536):
        """The last hidden layer h(x) (n, width), so that ``y = h W3^T + b3``.

        Used to fit the output layer by least squares (a warm start for fitting); plain NumPy.

        Examples
        --------
        >>> net = ResidualMLP(width=16, depth=2, seed=0)
        >>> x = np.array([[0.0, 0.0, 1.0]])
        >>> h = net.features(x)
        >>> h.shape, bool(np.allclose(h @ net.W3.T, net(x)))         # y = h W3^T (no bias)
        ((1, 16), True)
        """
        from .activations import softplus

        x = self._check_x(x)
        out = np.empty((x.shape[0], self.width), self.dtype)
        for lo in range(0, x.shape[0], chunk_size):
            xs = x[lo:lo + chunk_size]
            h = softplus(xs @ self.W0.T + (self.b0 if self.bias else 0.0))
            for blk in range(self.depth):
                a = softplus(h @ self.W1[blk].T + (self.b1[blk] if self.bias else 0.0))
                h = softplus(h + a @ self.W2[blk].T + (self.b2[blk] if self.bias else 0.0))
            out[lo:lo + chunk_size] = h
        return out

    def _bias_args(self):
        return self.b0, self.b1, self.b2, self.b3

    def _forward_small(self, x, D, m, k, Y):
        if D is None:
            D = np.broadcast_to(np.eye(self.in_dim, m, dtype=self.dtype), (x.shape[0],
                                                                            self.in_dim, m))
        b0, b1, b2, b3 = self._bias_args()
        K.small_forward(x, D, self.W0, b0, self.W1, b1, self.W2, b2, self.W3, b3, self.bias,
                        m, k, Y)

    def _first_layer(self, x, D, m, Z):
        """Pre-activation streams of the input layer: W0 x, W0 d_a, and zero second order."""
        np.matmul(x, self.W0.T, out=Z[:, 0, :])
        for a in range(m):
            if D is None:
                Z[:, 1 + a, :] = self.W0[:, a]
            else:
                np.matmul(D[:, :, a], self.W0.T, out=Z[:, 1 + a, :])
        Z[:, 1 + m:, :] = 0.0

    def _forward_blas(self, x, D, m, k, Y):
        n = x.shape[0]
        c = min(self._chunk(n_streams(m, k)), n)
        plan = _parallel.plan(n, c)
        if plan is None:  # threaded products and threaded passes, chunk after chunk
            self._forward_chunks(x, D, m, k, Y, c, range(-(-n // c)), K.softplus_jet)
            return
        workers, c = plan
        n_chunks = -(-n // c)
        # whole chunks per worker: single-threaded products and serial passes (_parallel.py)
        queue = _parallel.TaskQueue(n_chunks)
        _parallel.run(lambda _: self._forward_chunks(x, D, m, k, Y, c, queue,
                                                     K.softplus_jet_serial), workers, queue)

    def _forward_chunks(self, x, D, m, k, Y, c, chunks, act):
        """The jet streams of the chunks ``chunks`` (indices of c-point slices of x) into Y.

        ``act`` is the fused softplus jet kernel (threaded or serial); H, T1, T2 and sig are
        this call's own scratch, so that several calls can run side by side.
        """
        n = x.shape[0]
        S = n_streams(m, k)
        w = self.width
        H = np.empty((c, S, w), self.dtype)
        T1 = np.empty((c, S, w), self.dtype)
        T2 = np.empty((c, S, w), self.dtype)
        sig = np.empty((c, w), self.dtype)
        b0, b1, b2, b3 = self._bias_args()
        for i in chunks:
            lo, hi = i * c, min(i * c + c, n)
            r = hi - lo
            h, t1, t2, sg = H[:r], T1[:r], T2[:r], sig[:r]
            h2, t12, t22 = h.reshape(r * S, w), t1.reshape(r * S, w), t2.reshape(r * S, w)
            self._first_layer(x[lo:hi], None if D is None else D[lo:hi], m, t1)
            act(t1, t1, b0, h, sg, m, k, False, self.bias)
            for blk in range(self.depth):
                np.matmul(h2, self.W1[blk].T, out=t12)
                act(t1, t1, b1[blk], t1, sg, m, k, False, self.bias)
                np.matmul(t12, self.W2[blk].T, out=t22)
                act(t2, h, b2[blk], h, sg, m, k, True, self.bias)
            np.matmul(h2, self.W3.T, out=Y[lo:hi].reshape(r * S, self.out_dim))
            if self.bias:
                Y[lo:hi, 0, :] += b3

    # ------------------------------------------------------------------ reverse mode
    def vjp(self, x, dy, dJ=None, directions=None):
        """Gradient of ``sum(dy * y) + sum(dJ * J)`` with respect to all parameters.

        Parameters
        ----------
        x : (n, in_dim) float array
        dy : (n, out_dim) float array, cotangent of the value
        dJ : (n, out_dim, in_dim) float array, optional, cotangent of the Jacobian; with
            ``directions`` D (n, in_dim, m) it is the cotangent (n, out_dim, m) of J @ D.
        directions : (n, in_dim, m) float array, optional

        Returns
        -------
        (n_params,) array in the network's dtype, laid out like :meth:`pack`.

        Examples
        --------
        >>> net = ResidualMLP(width=8, depth=1, seed=0)
        >>> x = np.array([[0.0, 0.0, 1.0]])
        >>> dy = np.array([[1.0, 0.0, 0.0]])                           # d y_0 / d theta
        >>> g = net.vjp(x, dy)
        >>> eps, e = 1e-6, np.zeros(net.n_params)
        >>> e[5] = eps
        >>> theta = net.pack()
        >>> fd = (net.unpack(theta + e)(x)[0, 0] - net.unpack(theta - e)(x)[0, 0]) / (2 * eps)
        >>> bool(abs(g[5] - fd) < 1e-7)                               # matches central differences
        True
        """
        x = self._check_x(x)
        n = x.shape[0]
        dy = self._check_cotangent(dy, (n, self.out_dim), "dy")
        D = None
        if directions is not None:
            D = self._check_directions(directions, n)
        if dJ is None:
            m = 0
            if D is not None:
                raise ValueError("directions= given without dJ")
        else:
            m = self.in_dim if D is None else D.shape[2]
            dJ = self._check_cotangent(dJ, (n, self.out_dim, m), "dJ")

        def loss_fn(y, JD, sl):
            return 0.0, dy[sl], None if dJ is None else dJ[sl]

        return self.value_and_grad(x, loss_fn, order=0 if m == 0 else 1, directions=D,
                                   _m=m)[1]

    def _check_cotangent(self, a, shape, name):
        a = as_float_array(a, name)
        if a.shape != shape:
            raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
        check_finite(a, name)
        return a.astype(self.dtype, copy=False)

    def value_and_grad(self, x, loss_fn, order=1, directions=None, _m=None):
        """Fused forward, loss and backward pass, chunk by chunk (the training step).

        Parameters
        ----------
        x : (n, in_dim) float array
        loss_fn : callable ``loss_fn(y, JD, sl) -> (loss, dy, dJD)``
            Called once per chunk with the chunk's value y (c, out_dim), first derivatives JD
            (c, out_dim, m) (``None`` at order 0) and the slice ``sl`` of the chunk in x. It
            returns the chunk's loss contribution and its cotangents (``dJD`` may be None).
            The total loss is the sum of the contributions, so a mean over all n points must
            divide by n inside ``loss_fn``. On the data-parallel path the chunks are run by
            worker threads in no fixed order: calls never overlap (they hold a lock), but
            ``loss_fn`` must not rely on the order of the slices.
        order : int, 0 or 1
        directions : (n, in_dim, m) float array, optional (default: the coordinate axes)

        Returns
        -------
        (loss, grad) : float, (n_params,) array

        Examples
        --------
        >>> net = ResidualMLP(width=8, depth=1, seed=0)
        >>> x = np.random.default_rng(0).standard_normal((32, 3))
        >>> def loss(y, JD, sl):      # mean |y - x|^2 + mean |J - I|^2, per chunk
        ...     r, E = y - x[sl], JD - np.eye(3)
        ...     n = len(x)
        ...     return ((r ** 2).sum() + (E ** 2).sum()) / n, 2 * r / n, 2 * E / n
        >>> value, grad = net.value_and_grad(x, loss, order=1)
        >>> grad.shape == (net.n_params,), value > 0
        (True, True)
        """
        x = self._check_x(x) if _m is None else x
        n = x.shape[0]
        order = check_order(order, (0, 1))
        D = directions
        if _m is None and D is not None:
            D = self._check_directions(D, n)
        m = _m if _m is not None else (0 if order == 0 else
                                       (self.in_dim if D is None else D.shape[2]))
        grad = np.zeros(self.n_params, dtype=self.dtype)
        if n == 0:
            return 0.0, grad
        if self.width <= SMALL_WIDTH:
            return self._value_and_grad_small(x, D, m, loss_fn, grad)
        return self._value_and_grad_blas(x, D, m, loss_fn, grad)

    def _grad_views(self, grad):
        return {name: grad[slice(*self._offsets[name])].reshape(shape)
                for name, shape in self._shapes.items()}

    def _value_and_grad_small(self, x, D, m, loss_fn, grad):
        n = x.shape[0]
        S = 1 + m
        if D is None:
            D = np.broadcast_to(np.eye(self.in_dim, max(m, 1), dtype=self.dtype),
                                (n, self.in_dim, max(m, 1)))
        Y = np.empty((n, S, self.out_dim), self.dtype)
        b0, b1, b2, b3 = self._bias_args()
        K.small_forward(x, D, self.W0, b0, self.W1, b1, self.W2, b2, self.W3, b3, self.bias,
                        m, 0, Y)
        y, JD = Y[:, 0, :], (np.swapaxes(Y[:, 1:, :], 1, 2) if m else None)
        loss, dy, dJD = loss_fn(y, JD, slice(0, n))
        Ybar = _pack_cotangents(dy, dJD, m, n, self.out_dim, self.dtype)
        import numba
        nblk = max(1, min(numba.get_num_threads(), n))
        g = {name: np.zeros((nblk,) + shape, np.float64) for name, shape in self._shapes.items()}
        K.small_vjp(x, D, self.W0, b0, self.W1, b1, self.W2, b2, self.W3, b3, self.bias, m,
                    Ybar.astype(np.float64), g["W0"], g["b0"], g["W1"], g["b1"], g["W2"],
                    g["b2"], g["W3"], g["b3"])
        views = self._grad_views(grad)
        for name in self._shapes:
            views[name][...] = g[name].sum(axis=0)
        return float(loss), grad

    def _value_and_grad_blas(self, x, D, m, loss_fn, grad):
        n = x.shape[0]
        c = min(self._chunk(1 + m), n)
        plan = _parallel.plan(n, c)
        if plan is None:  # threaded products and threaded passes, chunk after chunk
            losses = [0.0] * -(-n // c)
            self._grad_chunks(x, D, m, loss_fn, grad, c, range(len(losses)), losses,
                              K.softplus_jet, K.softplus_jet_back)
            return math.fsum(losses), grad
        workers, c = plan
        n_chunks = -(-n // c)
        losses = [0.0] * n_chunks
        # Whole chunks per worker (_parallel.py), each with its own gradient accumulator.
        # Chunks are dealt round-robin, not on demand, and the accumulators are added in
        # worker order, so that the gradient does not depend on timing. loss_fn is called
        # under a lock: it never runs concurrently with itself.
        lock = threading.Lock()

        def locked_loss(y, JD, sl):
            with lock:
                return loss_fn(y, JD, sl)

        def work(i):
            g = grad if i == 0 else np.zeros_like(grad)
            self._grad_chunks(x, D, m, locked_loss, g, c, range(i, n_chunks, workers), losses,
                              K.softplus_jet_serial, K.softplus_jet_back_serial)
            return g

        for g in _parallel.run(work, workers)[1:]:
            grad += g
        return math.fsum(losses), grad

    def _grad_chunks(self, x, D, m, loss_fn, grad, c, chunks, losses, act, act_back):
        """Forward, loss and backward pass of the chunks ``chunks``; adds into grad.

        The loss of chunk i goes to ``losses[i]``. ``act`` and ``act_back`` are the fused
        kernels (threaded or serial); the tape is this call's own.
        """
        n = x.shape[0]
        S = 1 + m
        w, L, o = self.width, self.depth, self.out_dim
        dt = self.dtype
        # tape, reused for every chunk
        Z0 = np.empty((c, S, w), dt)
        SG0 = np.empty((c, w), dt)
        H = np.empty((L + 1, c, S, w), dt)
        U = np.empty((L, c, S, w), dt)
        SGU = np.empty((L, c, w), dt)
        A = np.empty((L, c, S, w), dt)
        Zt = np.empty((L, c, S, w), dt)
        SGZ = np.empty((L, c, w), dt)
        Y = np.empty((c, S, o), dt)
        hbar = np.empty((c, S, w), dt)
        abar = np.empty((c, S, w), dt)
        tmp = np.empty((c, S, w), dt)
        gv = self._grad_views(grad)
        b0, b1, b2, b3 = self._bias_args()
        for i in chunks:
            lo, hi = i * c, min(i * c + c, n)
            r = hi - lo
            rows = r * S
            Dc = None if D is None else D[lo:hi]
            # forward, keeping the tape
            self._first_layer(x[lo:hi], Dc, m, Z0[:r])
            act(Z0[:r], Z0[:r], b0, H[0, :r], SG0[:r], m, 0, False, self.bias)
            for blk in range(L):
                np.matmul(_flat(H[blk], r), self.W1[blk].T, out=_flat(U[blk], r))
                act(U[blk, :r], U[blk, :r], b1[blk], A[blk, :r], SGU[blk, :r], m, 0, False,
                    self.bias)
                np.matmul(_flat(A[blk], r), self.W2[blk].T, out=_flat(Zt[blk], r))
                act(Zt[blk, :r], H[blk, :r], b2[blk], H[blk + 1, :r], SGZ[blk, :r], m, 0, True,
                    self.bias)
            np.matmul(_flat(H[L], r), self.W3.T, out=_flat(Y, r))
            if self.bias:
                Y[:r, 0, :] += b3
            y = Y[:r, 0, :]
            JD = np.swapaxes(Y[:r, 1:, :], 1, 2) if m else None
            loss, dy, dJD = loss_fn(y, JD, slice(lo, hi))
            losses[i] = float(loss)
            Ybar = _pack_cotangents(dy, dJD, m, r, o, dt)
            # backward
            Yb = Ybar.reshape(rows, o)
            gv["W3"] += Yb.T @ _flat(H[L], r)
            if self.bias:
                gv["b3"] += Ybar[:, 0, :].sum(axis=0)
            np.matmul(Yb, self.W3, out=_flat(hbar, r))
            for blk in range(L - 1, -1, -1):
                act_back(Zt[blk, :r], SGZ[blk, :r], hbar[:r], hbar[:r], m)
                gv["W2"][blk] += _flat(hbar, r).T @ _flat(A[blk], r)
                if self.bias:
                    gv["b2"][blk] += hbar[:r, 0, :].sum(axis=0)
                np.matmul(_flat(hbar, r), self.W2[blk], out=_flat(abar, r))
                act_back(U[blk, :r], SGU[blk, :r], abar[:r], abar[:r], m)
                gv["W1"][blk] += _flat(abar, r).T @ _flat(H[blk], r)
                if self.bias:
                    gv["b1"][blk] += abar[:r, 0, :].sum(axis=0)
                np.matmul(_flat(abar, r), self.W1[blk], out=_flat(tmp, r))
                hbar[:r] += tmp[:r]
            act_back(Z0[:r], SG0[:r], hbar[:r], hbar[:r], m)
            gv["W0"] += hbar[:r, 0, :].T @ x[lo:hi]
            for a in range(m):
                if Dc is None:
                    gv["W0"][:, a] += hbar[:r, 1 + a, :].sum(axis=0)
                else:
                    gv["W0"] += hbar[:r, 1 + a, :].T @ Dc[:, :, a]
            if self.bias:
                gv["b0"] += hbar[:r, 0, :].sum(axis=0)


def _flat(a, r):
    """The first r points of a (c, S, w) stream array as a (r * S, w) matrix (a view)."""
    return a[:r].reshape(r * a.shape[1], -1)


def _pack_cotangents(dy, dJD, m, n, o, dtype):
    """Stack the cotangents of y (n, o) and JD (n, o, m) as streams (n, 1 + m, o)."""
    Ybar = np.empty((n, 1 + m, o), dtype)
    Ybar[:, 0, :] = dy
    if m:
        if dJD is None:
            Ybar[:, 1:, :] = 0.0
        else:
            Ybar[:, 1:, :] = np.swapaxes(dJD, 1, 2)
    return Ybar


def _unpack_streams(Y, order, m, k):
    """Split output streams (n, S, o) into y, J (n, o, m), D2 (n, o, k, k)."""
    y = Y[:, 0, :]
    if order == 0:
        return np.ascontiguousarray(y)
    J = np.ascontiguousarray(np.swapaxes(Y[:, 1:1 + m, :], 1, 2))
    if order == 1:
        return np.ascontiguousarray(y), J
    n, _, o = Y.shape
    D2 = np.empty((n, o, k, k), Y.dtype)
    q = 1 + m
    for a, b in _pairs(k):
        D2[:, :, a, b] = Y[:, q, :]
        D2[:, :, b, a] = Y[:, q, :]
        q += 1
    return np.ascontiguousarray(y), J, D2


# ---------------------------------------------------------------------------------------------
# .npz files: atomic writes, never unpickling
# ---------------------------------------------------------------------------------------------

def save_npz(path, arrays: dict) -> Path:
    """Write ``arrays`` to ``path`` (.npz) through a temporary file, fsync and an atomic rename."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise ValueError(f"model files must end in .npz, got {path.name!r}")

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    # umask permissions, fsync before the rename (sns_np/_atomic.py)
    return write_file(path, write)
