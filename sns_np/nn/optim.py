"""First-order optimisers and learning-rate schedules on flat parameter vectors.

Every optimiser updates ``theta`` in place from a gradient of the same shape, keeps its state
in a few arrays (``state_dict`` / ``load_state_dict`` for checkpoints) and takes its learning
rate from a schedule evaluated at the step count.

For ``scipy.optimize``, :func:`scipy_objective` wraps a network and a loss into
``fun(theta) -> (loss, grad)`` for ``minimize(fun, theta0, jac=True, method="L-BFGS-B")``.

References
----------
Kingma, D. P., & Ba, J. (2015). Adam: A method for stochastic optimization. ICLR.
Tieleman, T., & Hinton, G. (2012). Lecture 6.5, RMSProp. COURSERA: Neural Networks.
Vyas, N., Morwani, D., Zhao, R., Shapira, I., Brandfonbrener, D., Janson, L., & Kakade, S.
(2024). SOAP: Improving and stabilizing Shampoo using Adam. arXiv:2409.11321.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.linalg

from .._validation import check_positive_float, check_positive_int
from ..errors import DivergenceError, ShapeError

__all__ = ["Schedule", "constant", "cosine", "step", "Optimizer", "SGD", "Adam", "RMSProp",
           "SOAP", "optimizer_class", "make_optimizer", "scipy_objective"]


# ------------------------------------------------------------------------------ schedules

class Schedule:
    """A learning rate as a function of the step count t = 0, 1, 2, ...

    Parameters
    ----------
    kind : {"constant", "cosine", "step"}
    lr : float
        Initial (peak) learning rate.
    total : int, cosine only
        Steps over which the rate decays from ``lr`` to ``lr_min``; constant afterwards.
    lr_min : float, cosine only
    every, gamma : step only
        Multiply the rate by ``gamma`` every ``every`` steps.
    warmup : int
        Linear ramp from lr / warmup to lr over the first ``warmup`` steps (all kinds).

    Examples
    --------
    >>> s = Schedule("cosine", lr=1e-3, total=100, lr_min=1e-5, warmup=10)
    >>> [float(f"{s(t):.3g}") for t in (0, 9, 50, 100, 200)]
    [0.0001, 0.00098, 0.000505, 1e-05, 1e-05]
    """

    KINDS = ("constant", "cosine", "step")

    def __init__(self, kind="constant", lr=1e-3, total=None, lr_min=0.0, every=None, gamma=0.5,
                 warmup=0):
        if kind not in self.KINDS:
            raise ValueError(f"unknown schedule {kind!r}; expected one of {self.KINDS}")
        self.kind = kind
        self.lr = check_positive_float(lr, "lr")
        self.lr_min = check_positive_float(lr_min, "lr_min", allow_zero=True)
        self.warmup = check_positive_int(warmup, "warmup", minimum=0)
        if kind == "cosine":
            if total is None:
                raise ValueError("the cosine schedule needs total= (number of decay steps)")
            self.total = check_positive_int(total, "total")
        else:
            self.total = None
        if kind == "step":
            if every is None:
                raise ValueError("the step schedule needs every= (steps between decays)")
            self.every = check_positive_int(every, "every")
            self.gamma = check_positive_float(gamma, "gamma")
        else:
            self.every, self.gamma = None, gamma

    def __call__(self, t: int) -> float:
        if self.kind == "constant":
            lr = self.lr
        elif self.kind == "cosine":
            lr = self.cosine_at(min(t, self.total) / self.total)
        else:
            lr = self.lr * self.gamma ** (t // self.every)
        if self.warmup and t < self.warmup:
            lr *= (t + 1) / self.warmup
        return lr

    def cosine_at(self, frac: float) -> float:
        """The cosine decay from ``lr`` to ``lr_min`` at the fraction ``frac`` (0 - 1) of its
        length, without the warm-up (a fit with a time budget follows it on the clock).

        Examples
        --------
        >>> Schedule("cosine", 1.0, total=10, lr_min=0.0).cosine_at(0.5)
        0.5
        """
        return self.lr_min + 0.5 * (self.lr - self.lr_min) * (1.0 + math.cos(math.pi * frac))

    def __repr__(self):
        return f"Schedule({self.kind!r}, lr={self.lr:g})"


def constant(lr):
    """A constant learning rate.

    Examples
    --------
    >>> constant(1e-3)(0), constant(1e-3)(10**6)
    (0.001, 0.001)
    """
    return Schedule("constant", lr)


def cosine(lr, total, lr_min=0.0, warmup=0):
    """Cosine decay from ``lr`` to ``lr_min`` over ``total`` steps.

    Examples
    --------
    >>> s = cosine(1.0, total=4)
    >>> [round(s(t), 4) for t in range(6)]                          # flat after total
    [1.0, 0.8536, 0.5, 0.1464, 0.0, 0.0]
    """
    return Schedule("cosine", lr, total=total, lr_min=lr_min, warmup=warmup)


def step(lr, every, gamma=0.5):
    """Multiply the rate by ``gamma`` every ``every`` steps.

    Examples
    --------
    >>> s = step(1.0, every=2, gamma=0.1)
    >>> [float(f"{s(t):.3g}") for t in range(5)]
    [1.0, 1.0, 0.1, 0.1, 0.01]
    """
    return Schedule("step", lr, every=every, gamma=gamma)


def _as_schedule(lr):
    if isinstance(lr, Schedule) or callable(lr):
        return lr
    return constant(lr)


# ------------------------------------------------------------------------------ optimisers

#: parameter vectors at least this long are updated by a fused Numba kernel (Adam): one pass
#: over memory instead of eight NumPy passes (docs/performance.md)
_FUSED_MIN = 4096

class Optimizer:
    """Base class: holds the schedule, the step count and named state arrays.

    Examples
    --------
    >>> opt = Adam(lr=0.1)                                         # any subclass
    >>> theta = np.array([1.0, -2.0])
    >>> for _ in range(200):
    ...     _ = opt.step(theta, 2 * theta)                          # minimise |theta|^2
    >>> bool(np.abs(theta).max() < 0.05), opt.t
    (True, 200)
    """

    _state_names: tuple = ()

    def __init__(self, lr):
        self.schedule = _as_schedule(lr)
        self.t = 0
        self._state = {}

    def lr(self) -> float:
        """The learning rate of the next step.

        Examples
        --------
        >>> opt = SGD(lr=cosine(0.1, total=10))
        >>> opt.lr()
        0.1
        >>> _ = opt.step(np.zeros(2), np.ones(2))
        >>> round(opt.lr(), 6)
        0.097553
        """
        return float(self.schedule(self.t))

    def _buffers(self, theta):
        if not self._state:
            for name in self._state_names:
                self._state[name] = np.zeros_like(theta)
        ref = self._state[self._state_names[0]] if self._state_names else None
        if ref is not None and ref.shape != theta.shape:
            raise ShapeError(f"optimiser state has shape {ref.shape} but theta has "
                             f"{theta.shape}; use a new optimiser for a new model")
        return [self._state[name] for name in self._state_names]

    def step(self, theta: np.ndarray, grad: np.ndarray) -> np.ndarray:
        """Update ``theta`` in place from ``grad``; returns theta.

        Examples
        --------
        >>> opt = SGD(lr=0.5)
        >>> opt.step(np.array([1.0, 2.0]), np.array([1.0, 1.0]))       # theta -= lr g, in place
        array([0.5, 1.5])
        """
        if not isinstance(theta, np.ndarray) or not np.issubdtype(theta.dtype, np.floating):
            raise ShapeError("theta must be a floating numpy array (updated in place)")
        grad = np.asarray(grad)
        if grad.shape != theta.shape:
            raise ShapeError(f"grad has shape {grad.shape}, expected {theta.shape}")
        if not np.all(np.isfinite(grad)):
            raise DivergenceError(
                f"non-finite gradient at step {self.t}; parameters left unchanged")
        self._update(theta, grad.astype(theta.dtype, copy=False), self.lr())
        self.t += 1
        return theta

    def _update(self, theta, g, lr):  # pragma: no cover - abstract
        raise NotImplementedError

    def state_dict(self) -> dict:
        """Arrays describing the optimiser (for checkpoints); restore with load_state_dict.

        Examples
        --------
        >>> opt = Adam(lr=0.1)
        >>> _ = opt.step(np.zeros(3), np.ones(3))
        >>> state = opt.state_dict()
        >>> sorted(state), int(state["t"])
        (['kind', 'm', 't', 'v'], 1)
        """
        out = {"t": np.array(self.t), "kind": np.array(type(self).__name__)}
        for name, arr in self._state.items():
            out[name] = arr.copy()
        return out

    def load_state_dict(self, state: dict) -> Optimizer:
        """Restore the state written by :meth:`state_dict` (same optimiser class); returns self.

        Examples
        --------
        >>> a, b = Adam(lr=0.1), Adam(lr=0.1)
        >>> theta_a, theta_b = np.zeros(2), np.zeros(2)
        >>> _ = a.step(theta_a, np.ones(2))
        >>> theta_b[:] = theta_a
        >>> _ = b.load_state_dict(a.state_dict())                      # resume where a stopped
        >>> g = np.array([0.5, -1.0])
        >>> bool(np.array_equal(a.step(theta_a, g), b.step(theta_b, g)))
        True
        """
        kind = str(state.get("kind", ""))
        if kind != type(self).__name__:
            raise ValueError(f"optimiser state is for {kind!r}, not {type(self).__name__!r}")
        self.t = int(state["t"])
        self._state = {name: np.array(state[name]) for name in self._state_names
                       if name in state}
        return self

    @classmethod
    def check_state_layout(cls, layout: dict, n_theta: int, prefix: str = "") -> None:
        """Refuse state arrays that cannot be this optimiser's, from shapes and dtypes alone.

        A checkpoint loader calls this before it reads any array, with the shapes and
        dtypes the file declares: each array of Adam, RMSProp and SGD is a vector of
        ``n_theta`` numbers. :meth:`load_state_dict` checks what it reads again.

        Parameters
        ----------
        layout : dict
            ``{name: (shape, dtype)}`` for the arrays of :meth:`state_dict` other than
            "kind" and "t".
        n_theta : int
        prefix : str
            Put before each name in the error (a file's field names).

        Raises
        ------
        ValueError
            Naming the first array that does not fit.

        Examples
        --------
        >>> Adam.check_state_layout({"m": ((5,), np.dtype(float))}, 5)
        >>> Adam.check_state_layout({"m": ((5, 1), np.dtype(float))}, 5, prefix="opt.")
        Traceback (most recent call last):
            ...
        ValueError: field 'opt.m' must be a vector of 5 numbers, got float64 of shape (5, 1)
        """
        for name, (shape, dtype) in layout.items():
            if np.dtype(dtype).kind not in "fiu" or tuple(shape) != (n_theta,):
                raise ValueError(f"field {prefix + name!r} must be a vector of {n_theta} "
                                 f"numbers, got {dtype} of shape {shape}")


class SGD(Optimizer):
    """Gradient descent with optional (Nesterov) momentum.

    buf = momentum buf + g;  theta -= lr (g + momentum buf if nesterov else buf)

    Examples
    --------
    >>> opt = SGD(lr=0.1, momentum=0.9)
    >>> theta = np.array([1.0])
    >>> for _ in range(3):
    ...     _ = opt.step(theta, np.array([1.0]))
    >>> theta.round(4)                              # steps 0.1, 0.19, 0.271
    array([0.439])
    """

    _state_names = ("buf",)

    def __init__(self, lr=1e-2, momentum=0.0, nesterov=False):
        super().__init__(lr)
        self.momentum = check_positive_float(momentum, "momentum", allow_zero=True)
        self.nesterov = bool(nesterov)

    def _update(self, theta, g, lr):
        if self.momentum == 0.0:
            theta -= lr * g
            return
        (buf,) = self._buffers(theta)
        buf *= self.momentum
        buf += g
        theta -= lr * (g + self.momentum * buf if self.nesterov else buf)


def _adam_direction(g, m, v, b1, b2, c2, eps):
    """Adam's moments ``m``, ``v`` updated in place with the gradient ``g``; returns the
    direction ``m / (sqrt(c2 v) + eps)``, ``c2 = 1 / (1 - b2^t)`` (``m``'s own bias correction
    is left to the caller's rate)."""
    m *= b1
    m += (1.0 - b1) * g
    v *= b2
    v += (1.0 - b2) * (g * g)
    return m / (np.sqrt(v * c2) + eps)


class Adam(Optimizer):
    """Adam (Kingma & Ba 2015).

    m = b1 m + (1 - b1) g;   v = b2 v + (1 - b2) g^2          (first and second moments)
    m^ = m / (1 - b1^t);     v^ = v / (1 - b2^t)              (bias correction, t from 1)
    theta -= lr m^ / (sqrt(v^) + eps)

    Examples
    --------
    >>> opt = Adam(lr=0.1)
    >>> theta = np.array([1.0, -1.0])
    >>> opt.step(theta, np.array([3.0, -0.001]))   # first step: lr sign(g), bias-corrected
    array([ 0.9     , -0.900001])
    """

    _state_names = ("m", "v")

    def __init__(self, lr=1e-3, betas=(0.9, 0.999), eps=1e-8):
        super().__init__(lr)
        b1, b2 = betas
        if not (0.0 <= b1 < 1.0 and 0.0 <= b2 < 1.0):
            raise ValueError(f"betas must lie in [0, 1), got {betas}")
        self.b1, self.b2 = float(b1), float(b2)
        self.eps = check_positive_float(eps, "eps")

    def _update(self, theta, g, lr):
        m, v = self._buffers(theta)
        t = self.t + 1
        mhat_scale = 1.0 / (1.0 - self.b1 ** t)
        vhat_scale = 1.0 / (1.0 - self.b2 ** t)
        if theta.ndim == 1 and theta.flags.c_contiguous and theta.size >= _FUSED_MIN:
            # one pass over memory, on Numba's threads
            from ._kernels import adam_update, start_threads
            start_threads()
            adam_update(theta, g, m, v, lr * mhat_scale, self.b1, self.b2, vhat_scale,
                        self.eps)
            return
        theta -= (lr * mhat_scale) * _adam_direction(g, m, v, self.b1, self.b2, vhat_scale,
                                                     self.eps)


class RMSProp(Optimizer):
    """RMSProp with momentum, in the form of PyTorch's ``RMSprop`` (which the reference uses).

    v = alpha v + (1 - alpha) g^2;   d = g / (sqrt(v) + eps)
    buf = momentum buf + d;          theta -= lr buf     (theta -= lr d without momentum)

    The reference fits surfaces with lr 1e-4 and momentum 0.9 (alpha 0.99, eps 1e-8).

    Examples
    --------
    >>> opt = RMSProp(lr=0.01, momentum=0.0)
    >>> theta = np.array([1.0])
    >>> opt.step(theta, np.array([2.0]))           # v = 0.01 g^2: the first step is 10 lr
    array([0.9])
    """

    _state_names = ("v", "buf")

    def __init__(self, lr=1e-4, alpha=0.99, eps=1e-8, momentum=0.9):
        super().__init__(lr)
        if not 0.0 <= alpha < 1.0:
            raise ValueError(f"alpha must lie in [0, 1), got {alpha}")
        self.alpha = float(alpha)
        self.eps = check_positive_float(eps, "eps")
        self.momentum = check_positive_float(momentum, "momentum", allow_zero=True)

    def _update(self, theta, g, lr):
        v, buf = self._buffers(theta)
        v *= self.alpha
        v += (1.0 - self.alpha) * (g * g)
        d = g / (np.sqrt(v) + self.eps)
        if self.momentum:
            buf *= self.momentum
            buf += d
            theta -= lr * buf
        else:
            theta -= lr * d


class SOAP(Optimizer):
    """Adam in the eigenbasis of Shampoo's preconditioner for the weight matrices named by
    ``matrices``, plain Adam for every other parameter (Vyas et al. 2024).

    For each matrix, with ``G`` its gradient (m x n)::

        L = bs L + (1 - bs) G G^T;   R = bs R + (1 - bs) G^T G        (every step)
        Q_L, Q_R = eigenvectors of L, R, ascending                      (every ``every`` steps)
        G~ = Q_L^T G Q_R;   m = b1 m + (1 - b1) G~;   v = b2 v + (1 - b2) G~^2
        D = m^ / (sqrt(v^) + eps), each coordinate clipped to [-clip, clip]  (^: bias-corrected)
        W -= lr Q_L D Q_R^T

    Adam's per-coordinate scaling then acts along the directions in which the gradients of
    the matrix vary, not along its rows and columns: the update is the same whatever
    orthogonal change of basis the layer's inputs and outputs are written in (the property
    the tests check), which Adam's is not. When the bases change, the first moment is carried
    into the new ones exactly; the second moment keeps its index (the eigenvalues are sorted,
    so index i stays the i-th smallest direction), as its authors do.

    Two guards, not in SOAP's paper, keep it stable at the rates a surface fit uses
    (docs/fitting.md, "SOAP's guards"):

    * the direction ``m^ / (sqrt(v^) + eps)`` is clipped to ``[-clip, clip]`` per
      coordinate of the eigenbasis. A steady Adam direction stays within [-1, 1] (``m^2 <=
      v`` when the gradient's statistics do not change); SOAP's can leave it after a change
      of basis, when a first moment carried into a direction meets the second moment of a
      quieter one kept by index (coordinates of 150 to 490 at the first changes of basis
      when fitting SPIKE's exact map, and a divergence at the end of the warm-up);
    * a gradient longer than ``grad_clip`` times the running mean of the gradient's norm
      (decay 0.98, from the 12th step) is shortened to that length. With the clip alone
      the same fit reached 1.05 degrees of normal error in 325 steps and diverged to 75
      degrees a hundred steps later, at a rate Adam keeps.

    Per step it costs six products of each matrix's size (each 34 MFLOP for 256 x 256) and,
    every ``every`` steps, two symmetric eigendecompositions; docs/fitting.md measures what
    that buys in a surface fit.

    Parameters
    ----------
    lr : float or Schedule
    matrices : sequence of (slice, shape)
        Where the matrices lie in ``theta``: a slice and a shape ``(m, n)``, or ``(k, m, n)``
        for ``k`` stacked matrices of one size (as :meth:`ResidualMLP.param_slices` returns
        them). Empty blocks are skipped; blocks may not overlap.
    betas : (b1, b2)
        Adam's moment decays (``b2`` from step ``early_b2[1] + 1`` on). SOAP's authors use
        0.95 for the second; in surface fits it was much better at equal steps on a mesh,
        level at the end of a full fit, and worse at the end on an exact map, so Adam's
        0.999 is kept (docs/fitting.md, "SOAP's constants").
    shampoo_beta : float
        Decay ``bs`` of the factors ``L`` and ``R``.
    eps : float
    every : int
        Steps between two eigendecompositions of the factors.
    clip : float or None
        Bound on each coordinate of the direction in the eigenbasis (None: no bound, as
        SOAP's authors).
    grad_clip : float or None
        Longest gradient, in running means of the gradient's norm (None: no bound, as
        SOAP's authors).
    early_b2 : (decay, steps) or None
        The second moment's decay for the first ``steps`` steps (None: ``betas[1]`` from the
        start). SOAP's authors use 0.95 throughout. In surface fits, 0.95 for the first
        thousand steps, then 0.999 (with the first and last layers preconditioned too),
        gained 15% on a detailed mesh at 3,500 steps and lost 30% on an exact map, so the
        fit does not use it (docs/fitting.md, "SOAP's constants"). The bias correction
        follows the weight the running mean has gathered across the change.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.random.default_rng(0)
    >>> A = g.standard_normal((8, 8)) * np.logspace(0, 1, 8)    # an ill-conditioned problem
    >>> B = g.standard_normal((8, 8))
    >>> theta = np.zeros(64)
    >>> opt = SOAP(lr=0.05, matrices=[(slice(0, 64), (8, 8))])
    >>> for _ in range(300):
    ...     W = theta.reshape(8, 8)
    ...     _ = opt.step(theta, (2 * A.T @ (A @ W - B)).ravel())   # min |A W - B|^2
    >>> bool(np.abs(A @ theta.reshape(8, 8) - B).max() < 1e-2)
    True
    """

    def __init__(self, lr=1e-3, matrices=(), betas=(0.9, 0.999), shampoo_beta=0.95, eps=1e-8,
                 every=10, clip=1.0, grad_clip=2.0, early_b2=None):
        super().__init__(lr)
        b1, b2 = betas
        if not (0.0 <= b1 < 1.0 and 0.0 <= b2 < 1.0):
            raise ValueError(f"betas must lie in [0, 1), got {betas}")
        if early_b2 is not None:
            try:
                decay, steps = early_b2
            except (TypeError, ValueError):
                raise ValueError(f"early_b2 must be a pair (decay, steps) or None, got "
                                 f"{early_b2!r}") from None
            if not 0.0 <= decay < 1.0:
                raise ValueError(f"early_b2's decay must lie in [0, 1), got {decay!r}")
            early_b2 = (float(decay), check_positive_int(steps, "early_b2's steps"))
        self.early_b2 = early_b2
        if not 0.0 <= shampoo_beta < 1.0:
            raise ValueError(f"shampoo_beta must lie in [0, 1), got {shampoo_beta}")
        self.b1, self.b2, self.bs = float(b1), float(b2), float(shampoo_beta)
        self.eps = check_positive_float(eps, "eps")
        self.every = check_positive_int(every, "every")
        self.clip = None if clip is None else check_positive_float(clip, "clip")
        self.grad_clip = None if grad_clip is None else check_positive_float(grad_clip,
                                                                             "grad_clip")
        self.matrices = _matrix_blocks(matrices)

    def _blocks(self, theta):
        """The blocks as (start, k, m, n), checked against ``theta``; and the other indices."""
        key = theta.size
        if getattr(self, "_key", None) != key:
            taken = np.zeros(theta.size, dtype=bool)
            for start, k, m, n in self.matrices:
                stop = start + k * m * n
                if stop > theta.size:
                    raise ShapeError(f"SOAP: the matrices at [{start}, {stop}) do not lie "
                                     f"inside theta of length {theta.size}")
                if taken[start:stop].any():
                    raise ShapeError(f"SOAP: the matrices at [{start}, {stop}) overlap "
                                     "another block")
                taken[start:stop] = True
            self._rest, self._key = np.flatnonzero(~taken), key
        return self._rest

    def _buffers_soap(self, theta):
        rest = self._blocks(theta)
        st = self._state
        if not st:
            dt = theta.dtype
            st["rest_m"] = np.zeros(rest.size, dt)
            st["rest_v"] = np.zeros(rest.size, dt)
            for i, (_, k, m, n) in enumerate(self.matrices):
                for name, shape in _soap_state_shapes(k, m, n):
                    if name.startswith("Q"):        # the bases start as the identity
                        eye = np.eye(shape[1], dtype=dt)
                        st[f"{name}{i}"] = np.broadcast_to(eye, shape).copy()
                    else:
                        st[f"{name}{i}"] = np.zeros(shape, dt)
        elif st["rest_m"].shape != rest.shape or st["rest_m"].dtype != theta.dtype:
            raise ShapeError(f"optimiser state does not match theta of length {theta.size} "
                             f"and dtype {theta.dtype}; use a new optimiser for a new model")
        return rest

    def _update(self, theta, g, lr):
        from . import _parallel

        rest = self._buffers_soap(theta)
        st = self._state
        if self.grad_clip is not None:
            g = self._shorten(g)
        t = self.t + 1
        c1 = lr / (1.0 - self.b1 ** t)
        b2, c2 = self._second_decay(t)
        theta[rest] -= c1 * _adam_direction(g[rest], st["rest_m"], st["rest_v"], self.b1,
                                            b2, c2, self.eps)
        tasks = []                  # one per matrix: (its block, its index in the stack)
        for i, (start, k, p, q) in enumerate(self.matrices):
            stop = start + k * p * q
            arrays = (g[start:stop].reshape(k, p, q), theta[start:stop].reshape(k, p, q),
                      *(st[f"{a}{i}"] for a in ("L", "R", "QL", "QR", "m", "v")))
            tasks += [(arrays, j) for j in range(k)]
        rebase = self.t % self.every == 0
        bs = self.bs if self.t else 0.0
        # the clip applies to m^ / sqrt(v^); the direction below leaves m^'s factor to c1
        bound = None if self.clip is None else self.clip * (1.0 - self.b1 ** t)

        def one(n):
            arrays, j = tasks[n]
            self._matrix_step(*(a[j] for a in arrays), c1, b2, c2, bs, rebase, bound)

        # whole matrices per worker, single-threaded products (as the engine's jets run)
        _parallel.for_each(one, len(tasks))

    def _second_decay(self, t):
        """The second moment's decay at step ``t`` (from 1) and its bias correction, one over
        the weight the running mean has gathered: ``1 - b2^t`` with one decay, and with
        ``early_b2 = (b, T)`` after step T ``b2^(t - T) (1 - b^T) + 1 - b2^(t - T)``.

        Examples
        --------
        >>> opt = SOAP(early_b2=(0.5, 2))
        >>> [(b, round(1 / c, 5)) for b, c in map(opt._second_decay, (1, 2, 3))]
        [(0.5, 0.5), (0.5, 0.75), (0.999, 0.75025)]
        """
        if self.early_b2 is None:
            return self.b2, 1.0 / (1.0 - self.b2 ** t)
        b, T = self.early_b2
        if t <= T:
            return b, 1.0 / (1.0 - b ** t)
        late = self.b2 ** (t - T)
        return self.b2, 1.0 / (late * (1.0 - b ** T) + 1.0 - late)

    def _shorten(self, g):
        """``g``, shortened to ``grad_clip`` running means of the gradient's norm; the mean
        (of the shortened norms) updated."""
        norm = float(np.linalg.norm(g))
        mean = self._state.setdefault("gnorm", np.zeros(1))
        if not mean[0]:         # the first step (or a state written without the mean)
            mean[0] = norm
            return g
        if self.t > 10 and norm > self.grad_clip * mean[0]:
            g = g * (self.grad_clip * mean[0] / norm)
            norm = self.grad_clip * mean[0]
        mean[0] = 0.98 * mean[0] + 0.02 * norm
        return g

    def _matrix_step(self, G, W, L, R, QL, QR, M, V, c1, b2, c2, bs, rebase, bound):
        """One matrix's update, in place (the formulas of the class docstring)."""
        L *= bs
        L += (1.0 - bs) * (G @ G.T)
        R *= bs
        R += (1.0 - bs) * (G.T @ G)
        if rebase:      # new bases; the first moment carried into them exactly
            QLn = scipy.linalg.eigh(L, driver="evd", check_finite=False)[1].astype(L.dtype)
            QRn = scipy.linalg.eigh(R, driver="evd", check_finite=False)[1].astype(R.dtype)
            M[...] = (QLn.T @ QL) @ M @ (QR.T @ QRn)
            QL[...], QR[...] = QLn, QRn
        D = _adam_direction(QL.T @ G @ QR, M, V, self.b1, b2, c2, self.eps)
        if bound is not None:
            np.clip(D, -bound, bound, out=D)
        W -= c1 * (QL @ D @ QR.T)

    @classmethod
    def check_state_layout(cls, layout: dict, n_theta: int, prefix: str = "") -> None:
        """As :meth:`Optimizer.check_state_layout`, for SOAP's arrays: the moments of the
        parameters outside the matrices are vectors no longer than theta, every other array
        is a stack of matrices (which matrices is known only to an instance:
        :meth:`load_state_dict` checks their shapes).

        Examples
        --------
        >>> SOAP.check_state_layout({"rest_m": ((4,), np.dtype(float)),
        ...                          "QL0": ((2, 8, 8), np.dtype(float))}, 200)
        >>> SOAP.check_state_layout({"QL0": ((8, 8), np.dtype(float))}, 200)
        Traceback (most recent call last):
            ...
        ValueError: field 'QL0' must be a stack of matrices of numbers, got float64 of shape (8, 8)
        """
        stems = {a for a, _ in _soap_state_shapes(1, 1, 1)}     # L, R, QL, QR, m, v
        for name, (shape, dtype) in layout.items():
            shape = tuple(shape)
            if name in ("rest_m", "rest_v"):
                ok, want = len(shape) == 1 and shape[0] <= n_theta, \
                    f"a vector of at most {n_theta} numbers"
            elif name == "gnorm":
                ok, want = shape == (1,), "one number"
            else:
                stem = name.rstrip("0123456789")
                if stem not in stems or stem == name:
                    raise ValueError(f"field {prefix + name!r} is not part of SOAP's state")
                ok, want = len(shape) == 3, "a stack of matrices of numbers"
            if not ok or np.dtype(dtype).kind not in "fiu":
                raise ValueError(f"field {prefix + name!r} must be {want}, got {dtype} of "
                                 f"shape {shape}")

    def load_state_dict(self, state: dict) -> Optimizer:
        kind = str(state.get("kind", ""))
        if kind != type(self).__name__:
            raise ValueError(f"optimiser state is for {kind!r}, not {type(self).__name__!r}")
        names = ["rest_m", "rest_v"]
        for i, (_, k, m, n) in enumerate(self.matrices):
            for a, shape in _soap_state_shapes(k, m, n):
                names.append(f"{a}{i}")
                got = np.shape(state.get(f"{a}{i}", np.empty(shape)))
                if got != shape:
                    raise ValueError(f"SOAP state {a}{i} has shape {got}, expected {shape}: "
                                     f"it was written for other matrices")
        missing = [n for n in names if n not in state]
        if missing and int(state["t"]) > 0:
            raise ValueError(f"SOAP state lacks {missing}: it was written for other matrices")
        self.t = int(state["t"])
        # without "gnorm" (a state written with grad_clip=None) the running mean restarts
        self._state = {n: np.array(state[n]) for n in names + ["gnorm"] if n in state}
        return self


def _soap_state_shapes(k, m, n):
    """SOAP's arrays for ``k`` stacked m x n matrices: (name, shape), in one order."""
    return (("L", (k, m, m)), ("R", (k, n, n)), ("m", (k, m, n)), ("v", (k, m, n)),
            ("QL", (k, m, m)), ("QR", (k, n, n)))


def _matrix_blocks(matrices):
    """``[(slice, shape), ...]`` -> ``[(start, k, m, n), ...]``, empty blocks dropped."""
    out = []
    for item in matrices:
        try:
            sl, shape = item
            shape = tuple(int(d) for d in shape)
        except (TypeError, ValueError):
            raise ValueError(f"SOAP: each matrix block must be (slice, shape), "
                             f"got {item!r}") from None
        if len(shape) == 2:
            shape = (1, *shape)
        if len(shape) != 3 or min(shape) < 0:
            raise ValueError(f"SOAP: a block's shape must be (m, n) or (k, m, n), got {shape}")
        if not isinstance(sl, slice) or sl.step not in (None, 1) or sl.start is None \
                or sl.start < 0:
            raise ValueError(f"SOAP: a block's place in theta must be a slice with a start "
                             f"and step 1, got {sl!r}")
        size = shape[0] * shape[1] * shape[2]
        if sl.stop is not None and sl.stop - sl.start != size:
            raise ValueError(f"SOAP: the slice {sl!r} holds {sl.stop - sl.start} numbers but "
                             f"the shape {shape} needs {size}")
        if size:
            out.append((int(sl.start), *shape))
    return out


_OPTIMIZERS = {"adam": Adam, "rmsprop": RMSProp, "sgd": SGD, "soap": SOAP}


def optimizer_class(name: str) -> type:
    """The optimiser class called ``name``, in any case: "adam", "rmsprop", "sgd", "soap",
    or the ``kind`` a :meth:`Optimizer.state_dict` records.

    Examples
    --------
    >>> optimizer_class("SOAP").__name__, optimizer_class("rmsprop").__name__
    ('SOAP', 'RMSProp')
    >>> optimizer_class("nadam")
    Traceback (most recent call last):
        ...
    ValueError: unknown optimiser 'nadam'; expected one of ['adam', 'rmsprop', 'sgd', 'soap']
    """
    key = str(name).lower()
    if key not in _OPTIMIZERS:
        raise ValueError(f"unknown optimiser {name!r}; expected one of {sorted(_OPTIMIZERS)}")
    return _OPTIMIZERS[key]


def make_optimizer(name: str, lr, **options) -> Optimizer:
    """Optimiser by name: "adam", "rmsprop", "sgd" or "soap".

    Examples
    --------
    >>> opt = make_optimizer("rmsprop", 1e-4, momentum=0.9)
    >>> type(opt).__name__, opt.lr(), opt.momentum
    ('RMSProp', 0.0001, 0.9)
    >>> type(make_optimizer("Adam", cosine(1e-3, 100))).__name__
    'Adam'
    """
    return optimizer_class(name)(lr=lr, **options)


def scipy_objective(net, x, loss_fn: Callable, order: int = 1, directions=None):
    """``fun(theta) -> (loss, grad)`` in float64 for ``scipy.optimize.minimize(jac=True)``.

    Parameters
    ----------
    net : ResidualMLP
    x : (n, in_dim) float array of inputs
    loss_fn : callable, as in :meth:`ResidualMLP.value_and_grad`
    order : int, 0 or 1
    directions : (n, in_dim, m) float array, optional

    Examples
    --------
    >>> import numpy as np, scipy.optimize
    >>> from sns_np.nn import ResidualMLP
    >>> net = ResidualMLP(width=8, depth=1, seed=0)
    >>> x = np.random.default_rng(0).standard_normal((64, 3))
    >>> def loss(y, JD, sl):          # fit y = x, mean squared error
    ...     r = y - x[sl]
    ...     return (r ** 2).sum() / len(x), 2 * r / len(x), None
    >>> fun = scipy_objective(net, x, loss, order=0)
    >>> theta0 = net.pack()
    >>> res = scipy.optimize.minimize(fun, theta0, jac=True, method="L-BFGS-B",
    ...                               options=dict(maxiter=50))
    >>> bool(res.fun < 0.1 * fun(theta0)[0])
    True
    """
    def fun(theta):
        net.unpack(theta)
        loss, grad = net.value_and_grad(x, loss_fn, order=order, directions=directions)
        return float(loss), np.asarray(grad, dtype=np.float64)

    return fun
