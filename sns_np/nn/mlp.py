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

This class validates and delegates. Where each part lives:

* :mod:`sns_np.nn._engine`: the forward and reverse passes (BLAS/chunked and small-width Numba
  paths), plain functions of the network's parameters;
* :mod:`sns_np.nn._layout`: the parameter layout in the flat vector ``theta`` (the weight
  matrices are views into it) and the initialisation;
* :mod:`sns_np.nn._format`: the file format (``state``, ``from_state``, ``save``, ``load``);
* :mod:`sns_np.nn._parallel` and :mod:`sns_np.nn._kernels`: threads and Numba kernels.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._validation import (
    as_float_array,
    as_generator,
    check_finite,
    check_order,
    check_positive_float,
    check_positive_int,
)
from ..errors import ShapeError
from . import _engine, _format, _layout, _readout
from ._engine import SMALL_WIDTH, n_streams
from ._format import FORMAT, FORMAT_VERSION  # noqa: F401  (the file format's name, version)

__all__ = ["ResidualMLP", "n_streams"]


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
      (:mod:`sns_np.surface`) replaces it by a least-squares fit of the initial features
      (:meth:`fit_readout`).
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
        self._shapes, self._offsets, self.n_params = _layout.layout(
            self.in_dim, self.out_dim, self.width, self.depth, self.bias)
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

        ``w d + 2 depth w^2 + o w`` plus ``w + 2 depth w + o`` biases (d = in_dim,
        o = out_dim, w = width); for the reference network (3, 3, 256, 8): 1,050,112.

        Examples
        --------
        >>> ResidualMLP.count_params(3, 3, 256, 8)       # the reference surface network
        1050112
        >>> ResidualMLP.count_params(3, 3, 10, 2, bias=True)
        513
        """
        return _layout.count_params(in_dim, out_dim, width, depth, bias)

    # ------------------------------------------------------------------ parameters
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
        _layout.initialize(self, as_generator(seed))
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
        return _format.state(self, prefix)

    @classmethod
    def from_state(cls, data, prefix: str = "", source: str = "state") -> ResidualMLP:
        """Rebuild a network from :meth:`state` arrays, checking every field.

        ``data`` is a dict of arrays or an open file (:func:`sns_np._npz.load_npz`). The
        parameter count implied by the architecture fields is compared with the declared shape
        of ``theta`` before anything of that size is allocated, and the parameters are read
        straight into the new network's buffer (no random initialisation is drawn).

        Examples
        --------
        >>> net = ResidualMLP(width=4, depth=1, seed=0)
        >>> again = ResidualMLP.from_state(net.state())
        >>> bool(np.array_equal(again.pack(), net.pack()))
        True
        """
        return _format.from_state(cls, data, prefix, source)

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
        return _format.save(self, path)

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
        return _format.load(cls, path)

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
        D, m, k = self._streams(order, directions, second, n)
        Y = np.empty((n, n_streams(m, k), self.out_dim), dtype=self.dtype)
        if n:
            _engine.forward(self, x, D, m, k, Y)
        return _engine.unpack_streams(Y, order, m, k)

    def _streams(self, order, directions, second, n):
        """Checked ``(D, m, k)``: directions (or None), first-order and second-order counts."""
        if directions is None:
            if second is not None:
                raise ValueError("second= needs directions=")
            d = self.in_dim
            return None, (d if order >= 1 else 0), (d if order == 2 else 0)
        if order == 0:
            raise ValueError("directions= needs order 1 or 2")
        D = self._check_directions(directions, n)
        m = D.shape[2]
        if second is None:
            return D, m, (m if order == 2 else 0)
        if order != 2:
            raise ValueError("second= needs order=2")
        if isinstance(second, bool) or not isinstance(second, (int, np.integer)) or \
                not 0 <= second <= m:
            raise ValueError(f"second must be an integer in [0, {m}], got {second!r}")
        return D, m, int(second)

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
        return _engine.features(self, self._check_x(x), check_positive_int(chunk_size,
                                                                            "chunk_size"))

    def fit_readout(self, x, target, weights=None, *, rel_reg=1e-10, increment=False,
                    scale=1.0, current=None):
        """Fit the read-out layer (``W3``, and ``b3`` with biases) by linear least squares.

        The network is linear in its read-out, ``y = h W3^T + b3`` with ``h = features(x)``,
        so the best read-out of the current features at the points x is one solve of the
        ``width (+1)`` square normal equations, with weights w_k and a relative Tikhonov term:
        ``min sum_k w_k |[h_k, 1] T - r_k|^2 + lam |T|^2``,
        ``lam = rel_reg * trace(G) / size(G)`` for the Gram matrix ``G`` of the weighted
        features. Nothing else changes.

        Parameters
        ----------
        x : (n, in_dim) float array
        target : (n, out_dim) or (n,) float array
            (n, out_dim): the outputs wanted at x. (n,): the values wanted of the scalar
            read-out ``g = scale * mean_o y_o`` (a field's value); the same change is then
            added to every row of ``W3`` (and to every entry of ``b3``). A scalar target needs
            ``increment=True``.
        weights : (n,) float array, optional
            Non-negative weights of the points (quadrature weights, say); default all 1.
        rel_reg : float
            The relative Tikhonov weight (default 1e-10: only what keeps the solve regular).
        increment : bool
            False (default): replace the read-out by the fit, ``T`` pulled towards zero.
            True: fit the residual ``target - current`` and add the change, ``T`` pulled
            towards the current read-out (one Gauss-Newton step in the last layer).
        scale : float
            The factor of the scalar read-out (a (n,) target only).
        current : (n, out_dim) or (n,) float array, optional
            With ``increment``: the current outputs (or scalar read-out) at x, if the caller
            has them already; by default they are computed from the features in float64.

        Returns
        -------
        (width (+1), out_dim) or (width (+1),) float64 array
            The solution ``T``: the new read-out (transposed, ``b3`` as its last row) or, with
            ``increment``, the change added. When it is not finite (non-finite features or
            target) the network is left unchanged, and the caller can tell from this array.

        Examples
        --------
        >>> net = ResidualMLP(width=16, depth=1, seed=0)
        >>> x = np.random.default_rng(0).standard_normal((200, 3))
        >>> target = net.features(x) @ np.random.default_rng(1).standard_normal((16, 3))
        >>> T = net.fit_readout(x, target)                  # the targets are a read-out
        >>> bool(np.allclose(net(x), target, atol=1e-6)), T.shape
        (True, (16, 3))
        >>> d = net.fit_readout(x, target, increment=True)   # already fitted: nearly no change
        >>> bool(np.abs(d).max() < 1e-6)
        True
        """
        x = self._check_x(x)
        n, o = x.shape[0], self.out_dim
        target = as_float_array(target, "target")
        if target.shape not in ((n, o), (n,)):
            raise ShapeError(f"target must have shape ({n}, {o}) or ({n},), got {target.shape}")
        scalar = target.ndim == 1
        if scalar and not increment:
            raise ValueError("a scalar target (n,) is fitted as a change of the read-out: "
                             "pass increment=True")
        rel_reg = check_positive_float(rel_reg, "rel_reg", allow_zero=True)
        scale = float(scale)
        if not np.isfinite(scale) or scale == 0.0:
            raise ValueError(f"scale must be finite and non-zero, got {scale}")
        if current is not None:
            current = as_float_array(current, "current")
            if not increment or current.shape != target.shape:
                raise ShapeError(f"current (with increment=True only) must have the shape of "
                                 f"target, {target.shape}, got {current.shape}")
        if weights is not None:
            weights = as_float_array(weights, "weights")
            if weights.shape != (n,):
                raise ShapeError(f"weights must have shape ({n},), got {weights.shape}")
            check_finite(weights, "weights")
            if np.any(weights < 0):
                raise ValueError("weights must be non-negative")
        return _readout.fit(self, x, target, weights, rel_reg, increment, scale, current)

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

        return _engine.value_and_grad(self, x, D, m, loss_fn)[1]

    def _check_cotangent(self, a, shape, name):
        a = as_float_array(a, name)
        if a.shape != shape:
            raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
        check_finite(a, name)
        return a.astype(self.dtype, copy=False)

    def value_and_grad(self, x, loss_fn, order=1, directions=None, second=None,
                       concurrent_loss=False):
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
            worker threads in no fixed order: calls never overlap (they hold a lock, unless
            ``concurrent_loss``), but ``loss_fn`` must not rely on the order of the slices.
            At order 2 it is ``loss_fn(y, JD, D2D, sl) -> (loss, dy, dJD, dD2D)``, with the
            second derivatives D2D (c, out_dim, k, k) as :meth:`jet` returns them and their
            cotangent (may be None); ``D2D`` is symmetric, so only ``dD2D + dD2D^T`` counts.
        order : int, 0, 1 or 2
        directions : (n, in_dim, m) float array, optional (default: the coordinate axes)
        second : int, optional
            With ``directions`` and order 2: second derivatives along the pairs of the first
            ``second`` directions only (as in :meth:`jet`).
        concurrent_loss : bool
            True: ``loss_fn`` is safe to call from several threads at once, and the workers
            call it without the lock (a loss that searches the nearest points of a mesh then
            overlaps its search with the other workers' products). The result is the same.

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
        x = self._check_x(x)
        order = check_order(order)
        D, m, k = self._streams(order, directions, second, x.shape[0])
        return _engine.value_and_grad(self, x, D, m, loss_fn, k,
                                      concurrent=bool(concurrent_loss))

