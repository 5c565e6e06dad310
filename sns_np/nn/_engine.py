"""The derivative engine of :class:`~sns_np.nn.mlp.ResidualMLP`: forward jets and the fused
forward-loss-backward pass, as plain functions (private).

Like scikit-learn's ``_forward_pass`` and ``_backprop``, these functions take the network only
as the holder of its parameters (``W0`` ... ``b3``, ``width``, ``depth``, ``bias``, ``dtype``,
``chunk_size``) and do no validation: the methods of ``ResidualMLP`` check their input and
call them. ``docs/engine.md`` derives every line.

Two paths:

* small width (``width <= SMALL_WIDTH``): one Numba kernel runs a whole point per iteration
  (:func:`sns_np.nn._kernels.small_forward`, :func:`~sns_np.nn._kernels.small_vjp`);
* BLAS: the points are cut into chunks; every linear layer is one matrix product over all
  streams of a chunk and every activation one fused Numba pass. The chunks run either one
  after the other on threaded products and passes, or whole chunks per worker thread
  (:mod:`sns_np.nn._parallel`).

Streams (see ``_kernels.py``, "Stream layout"): a chunk of c points is a (c, S, w) array
holding, per point, the value, m first-order and k (k + 1) / 2 second-order streams.
"""

from __future__ import annotations

import math
import threading
from contextlib import contextmanager

import numpy as np

from . import _kernels as kern
from . import _parallel
from .activations import softplus

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


def pairs(k):
    """The second-order stream pairs (a, b), a <= b < k, in stream order."""
    return [(a, b) for a in range(k) for b in range(a, k)]


def chunk_points(net, S):
    """Most points per chunk for S streams (the network's ``chunk_size`` if it has one)."""
    if net.chunk_size is not None:
        return net.chunk_size
    return max(16, _ROWS_PER_CHUNK[net.dtype] // S)


def _biases(net):
    return net.b0, net.b1, net.b2, net.b3


def _grad_views(net, grad):
    """The parameter arrays of a flat gradient (n_params,), as views named like the network's."""
    return {name: grad[sl].reshape(shape) for name, (sl, shape) in net.param_slices().items()}


class _Workspace(threading.local):
    """Scratch memory for the tapes of the BLAS path, kept per thread and reused.

    A training step's tape is megabytes (width 128, 256 points per worker: 16 MB), and a
    fresh ``np.empty`` of that size is a fresh ``mmap`` whose pages fault in, zero-filled, at
    their first write: a third of a 512-point step of a detailed fit went to that
    (docs/performance.md, "The detailed fit's step"). The arrays of a call are carved out of
    one block per thread and nesting level (a loss function may call the network), which
    grows to the largest call seen and is kept until the thread ends or
    :func:`release_workspace` is called.
    """

    def __init__(self):
        self.blocks = []
        self.level = 0

    @contextmanager
    def arrays(self, dtype, *shapes):
        """Uninitialised arrays of ``shapes`` in ``dtype``, 64-byte aligned, valid inside
        the ``with`` (a view keeps its block alive, so a release meanwhile is harmless)."""
        dt = np.dtype(dtype)
        sizes = [math.prod(shape) * dt.itemsize for shape in shapes]
        starts = np.cumsum([0] + [-(-n // 64) * 64 for n in sizes]).tolist()
        level = self.level
        while len(self.blocks) <= level:
            self.blocks.append(np.empty(0, np.uint8))
        if self.blocks[level].nbytes < starts[-1] + 64:
            self.blocks[level] = np.empty(starts[-1] + 64, np.uint8)
        block = self.blocks[level]
        base = -block.ctypes.data % 64
        self.level += 1
        try:
            yield [block[base + a:base + a + n].view(dt).reshape(shape)
                   for a, n, shape in zip(starts, sizes, shapes)]
        finally:
            self.level -= 1


_workspace = _Workspace()


def release_workspace():
    """Free the engine's scratch memory: the calling thread's and, by ending them, that of
    the worker threads (started again when next needed).

    The engine keeps each thread's largest tape between calls (about 16 MB per worker for a
    detailed fit's step, 70 MB for the reference network's float64 training step); call this
    after a fit to return it.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.nn import ResidualMLP, release_workspace
    >>> net = ResidualMLP(width=64, depth=2, seed=0)
    >>> y = net.jet(np.eye(3), order=1)[0]      # keeps a tape for the next call
    >>> release_workspace()
    >>> bool(np.array_equal(net.jet(np.eye(3), order=1)[0], y))
    True
    """
    _workspace.blocks = []
    if not _parallel.inside_worker():    # a worker cannot end its own pool
        _parallel.shutdown()


def _small_layout(a):
    """``a`` as the small kernels take it: C-contiguous and writable. Numba compiles a kernel
    once per argument layout (seconds each, on the first call in a fresh environment), so
    broadcast or read-only directions are copied (n x in_dim x m numbers, small beside the
    jet) rather than compiled for."""
    return np.require(a, requirements=("C", "W"))


def _eye_directions(net, n, m):
    """The first m coordinate axes as directions (n, in_dim, m), without a copy per point."""
    return np.broadcast_to(np.eye(net.in_dim, m, dtype=net.dtype), (n, net.in_dim, m))


# ---------------------------------------------------------------------------------- forward

def forward(net, x, D, m, k, Y):
    """Output streams Y (n, S, out_dim) at checked points x (n, in_dim), n >= 1.

    ``D`` (n, in_dim, m) are the directions, or None for the coordinate axes; second-order
    streams along the pairs of the first k of them.
    """
    if net.width <= SMALL_WIDTH:
        forward_small(net, x, D, m, k, Y)
    else:
        forward_blas(net, x, D, m, k, Y)


def forward_small(net, x, D, m, k, Y):
    """The small-width path: one Numba kernel, one point per iteration."""
    if D is None:
        D = _eye_directions(net, x.shape[0], m)
    x, D = _small_layout(x), _small_layout(D)
    b0, b1, b2, b3 = _biases(net)
    kern.start_threads()
    kern.small_forward(x, D, net.W0, b0, net.W1, b1, net.W2, b2, net.W3, b3, net.bias, m, k, Y)


def first_layer(net, x, D, m, Z):
    """Pre-activation streams of the input layer: W0 x, W0 d_a, and zero second order."""
    np.matmul(x, net.W0.T, out=Z[:, 0, :])
    for a in range(m):
        if D is None:
            Z[:, 1 + a, :] = net.W0[:, a]
        else:
            np.matmul(D[:, :, a], net.W0.T, out=Z[:, 1 + a, :])
    Z[:, 1 + m:, :] = 0.0


def forward_blas(net, x, D, m, k, Y):
    """The BLAS path: chunk after chunk on all threads, or whole chunks per worker."""
    n = x.shape[0]
    c = min(chunk_points(net, n_streams(m, k)), n)
    plan = _parallel.plan(n, c)
    if plan is None:  # threaded products and threaded passes, chunk after chunk
        kern.start_threads()
        forward_chunks(net, x, D, m, k, Y, c, range(-(-n // c)), kern.softplus_jet)
        return
    workers, c = plan
    n_chunks = -(-n // c)
    # whole chunks per worker: single-threaded products and serial passes (_parallel.py)
    queue = _parallel.TaskQueue(n_chunks)
    _parallel.run(lambda _: forward_chunks(net, x, D, m, k, Y, c, queue,
                                           kern.softplus_jet_serial), workers, queue)


def forward_chunks(net, x, D, m, k, Y, c, chunks, act):
    """The jet streams of the chunks ``chunks`` (indices of c-point slices of x) into Y.

    ``act`` is the fused softplus jet kernel (threaded or serial); the scratch arrays come
    from this thread's workspace, so that several calls can run side by side.
    """
    n = x.shape[0]
    S = n_streams(m, k)
    w = net.width
    b0, b1, b2, b3 = _biases(net)
    with _workspace.arrays(net.dtype, (3, c, S, w), (c, w)) as (bufs, sig):
        for i in chunks:
            lo, hi = i * c, min(i * c + c, n)
            r = hi - lo
            h, t1, t2 = bufs[0, :r], bufs[1, :r], bufs[2, :r]
            sg = sig[:r]
            first_layer(net, x[lo:hi], None if D is None else D[lo:hi], m, t1)
            act(t1, t1, b0, h, sg, m, k, False, net.bias)
            # a kernel's output never overlaps its inputs ("Aliasing" in _kernels.py): the
            # block's next h goes to the scratch array that held A, and the two swap roles
            for blk in range(net.depth):
                np.matmul(flat(h, r), net.W1[blk].T, out=flat(t1, r))       # U
                act(t1, t1, b1[blk], t2, sg, m, k, False, net.bias)         # A = s(U)
                np.matmul(flat(t2, r), net.W2[blk].T, out=flat(t1, r))      # A W2^T
                act(t1, h, b2[blk], t2, sg, m, k, True, net.bias)           # next h
                h, t2 = t2, h
            np.matmul(flat(h, r), net.W3.T, out=Y[lo:hi].reshape(r * S, net.out_dim))
            if net.bias:
                Y[lo:hi, 0, :] += b3


def features(net, x, chunk_size):
    """The last hidden layer h(x) (n, width) in plain NumPy, ``chunk_size`` points at a time.

    The readable reference for the forward pass (no streams, no kernels): ``y = h W3^T + b3``.
    """
    out = np.empty((x.shape[0], net.width), net.dtype)
    for lo in range(0, x.shape[0], chunk_size):
        xs = x[lo:lo + chunk_size]
        h = softplus(xs @ net.W0.T + (net.b0 if net.bias else 0.0))
        for blk in range(net.depth):
            a = softplus(h @ net.W1[blk].T + (net.b1[blk] if net.bias else 0.0))
            h = softplus(h + a @ net.W2[blk].T + (net.b2[blk] if net.bias else 0.0))
        out[lo:lo + chunk_size] = h
    return out


def unpack_streams(Y, order, m, k):
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
    for a, b in pairs(k):
        D2[:, :, a, b] = Y[:, q, :]
        D2[:, :, b, a] = Y[:, q, :]
        q += 1
    return np.ascontiguousarray(y), J, D2


# ---------------------------------------------------------------------------------- reverse

def value_and_grad(net, x, D, m, loss_fn, k=0, concurrent=False):
    """Fused forward, loss and backward pass at checked x (n, in_dim): ``(loss, grad)``.

    ``D`` (n, in_dim, m) or None (the coordinate axes); m = 0 is the value alone; k > 0 adds
    the second derivatives along the pairs of the first k directions. The contract of
    ``loss_fn`` is that of :meth:`ResidualMLP.value_and_grad`.
    """
    grad = np.zeros(net.n_params, dtype=net.dtype)
    if x.shape[0] == 0:
        return 0.0, grad
    if net.width <= SMALL_WIDTH and k == 0:   # the small kernels stop at first order
        return value_and_grad_small(net, x, D, m, loss_fn, grad)
    return value_and_grad_blas(net, x, D, m, loss_fn, grad, k, concurrent)


def pack_cotangents(dy, dJD, m, n, o, dtype, dD2=None, k=0):
    """Stack the cotangents of y (n, o), JD (n, o, m) and D2D (n, o, k, k) as streams
    (n, S, o). A stored pair (a, b), a < b, is both D2D[a, b] and D2D[b, a]: its cotangent
    is the sum of theirs."""
    Ybar = np.empty((n, n_streams(m, k), o), dtype)
    Ybar[:, 0, :] = dy
    if m:
        if dJD is None:
            Ybar[:, 1:1 + m, :] = 0.0
        else:
            Ybar[:, 1:1 + m, :] = np.swapaxes(dJD, 1, 2)
    q = 1 + m
    for a, b in pairs(k):
        if dD2 is None:
            Ybar[:, q, :] = 0.0
        else:
            Ybar[:, q, :] = dD2[:, :, a, b] + (dD2[:, :, b, a] if a != b else 0.0)
        q += 1
    return Ybar


def value_and_grad_small(net, x, D, m, loss_fn, grad):
    """The small-width path: one forward kernel, the loss on all points, one reverse kernel.

    The reverse kernel accumulates float64 gradients per block of points (one block per
    Numba thread); the blocks are added here.
    """
    import numba

    n = x.shape[0]
    S = 1 + m
    if D is None:
        D = _eye_directions(net, n, max(m, 1))
    x, D = _small_layout(x), _small_layout(D)
    Y = np.empty((n, S, net.out_dim), net.dtype)
    b0, b1, b2, b3 = _biases(net)
    kern.start_threads()
    kern.small_forward(x, D, net.W0, b0, net.W1, b1, net.W2, b2, net.W3, b3, net.bias,
                       m, 0, Y)
    y, JD = Y[:, 0, :], (np.swapaxes(Y[:, 1:, :], 1, 2) if m else None)
    loss, dy, dJD = loss_fn(y, JD, slice(0, n))
    Ybar = pack_cotangents(dy, dJD, m, n, net.out_dim, net.dtype)
    nblk = max(1, min(numba.get_num_threads(), n))
    slices = net.param_slices()
    g = {name: np.zeros((nblk,) + shape, np.float64) for name, (_, shape) in slices.items()}
    kern.small_vjp(x, D, net.W0, b0, net.W1, b1, net.W2, b2, net.W3, b3, net.bias, m,
                   Ybar.astype(np.float64), g["W0"], g["b0"], g["W1"], g["b1"], g["W2"],
                   g["b2"], g["W3"], g["b3"])
    views = _grad_views(net, grad)
    for name in slices:
        views[name][...] = g[name].sum(axis=0)
    return float(loss), grad


def value_and_grad_blas(net, x, D, m, loss_fn, grad, k=0, concurrent=False):
    """The BLAS path: chunk after chunk on all threads, or round-robin chunks per worker
    (``concurrent``: their calls of ``loss_fn`` may overlap)."""
    n = x.shape[0]
    c = min(chunk_points(net, n_streams(m, k)), n)
    plan = _parallel.plan(n, c)
    if plan is None:  # threaded products and threaded passes, chunk after chunk
        kern.start_threads()
        losses = [0.0] * -(-n // c)
        grad_chunks(net, x, D, m, loss_fn, grad, c, range(len(losses)), losses,
                    kern.softplus_jet, _back_rule(k, serial=False), k)
        return math.fsum(losses), grad
    workers, c = plan
    n_chunks = -(-n // c)
    losses = [0.0] * n_chunks
    # Whole chunks per worker (_parallel.py), each with its own gradient accumulator.
    # Chunks are dealt round-robin, not on demand, and the accumulators are added in
    # worker order, so that the gradient does not depend on timing. loss_fn is called under
    # a lock, unless the caller says it may run concurrently with itself.
    lock = threading.Lock()

    def locked_loss(*args):
        with lock:
            return loss_fn(*args)

    call_loss = loss_fn if concurrent else locked_loss

    def work(i):
        g = grad if i == 0 else np.zeros_like(grad)
        grad_chunks(net, x, D, m, call_loss, g, c, range(i, n_chunks, workers), losses,
                    kern.softplus_jet_serial, _back_rule(k, serial=True), k)
        return g

    for g in _parallel.run(work, workers)[1:]:
        grad += g
    return math.fsum(losses), grad


def _back_rule(k, serial):
    """The fused backward kernel ``act_back(Z, sig, Abar, Zbar, m)``: the first-order rule,
    or with k > 0 the second-order one (threaded or serial)."""
    if not k:
        return kern.softplus_jet_back_serial if serial else kern.softplus_jet_back
    back2 = kern.softplus_jet2_back_serial if serial else kern.softplus_jet2_back
    return lambda Z, sig, Abar, Zbar, m: back2(Z, sig, Abar, Zbar, m, k)


def flat(a, r):
    """The first r points of a (c, S, w) stream array as a (r * S, w) matrix (a view)."""
    return a[:r].reshape(r * a.shape[1], -1)


def grad_chunks(net, x, D, m, loss_fn, grad, c, chunks, losses, act, act_back, k=0):
    """Forward, loss and backward pass of the chunks ``chunks``; adds into grad.

    The loss of chunk i goes to ``losses[i]``. ``act`` and ``act_back`` are the fused
    kernels (threaded or serial; :func:`_back_rule`); the tape comes from this thread's
    workspace. With k > 0 the streams include the second derivatives along the pairs of the
    first k directions, and ``act_back`` must be the second-order rule.
    """
    n = x.shape[0]
    S = n_streams(m, k)
    w, depth, o = net.width, net.depth, net.out_dim
    dt = net.dtype
    # the tape, reused for every chunk: hid[blk] is the input of block blk (hid[depth] feeds
    # the read-out), U, A the inner pre-activation and activation, Zt the block's
    # pre-activation; SG* the sigmoids of the value streams
    tape = _workspace.arrays(
        dt, (c, S, w), (c, w), (depth + 1, c, S, w), (depth, c, S, w), (depth, c, w),
        (depth, c, S, w), (depth, c, S, w), (depth, c, w), (c, S, o), *[(c, S, w)] * 5)
    gv = _grad_views(net, grad)
    b0, b1, b2, b3 = _biases(net)
    with tape as (Z0, SG0, hid, U, SGU, A, Zt, SGZ, Y, hbar, zbar, abar, ubar, tmp):
        for i in chunks:
            lo, hi = i * c, min(i * c + c, n)
            r = hi - lo
            rows = r * S
            Dc = None if D is None else D[lo:hi]
            # forward, keeping the tape
            first_layer(net, x[lo:hi], Dc, m, Z0[:r])
            act(Z0[:r], Z0[:r], b0, hid[0, :r], SG0[:r], m, k, False, net.bias)
            for blk in range(depth):
                np.matmul(flat(hid[blk], r), net.W1[blk].T, out=flat(U[blk], r))
                act(U[blk, :r], U[blk, :r], b1[blk], A[blk, :r], SGU[blk, :r], m, k, False,
                    net.bias)
                np.matmul(flat(A[blk], r), net.W2[blk].T, out=flat(Zt[blk], r))
                act(Zt[blk, :r], hid[blk, :r], b2[blk], hid[blk + 1, :r], SGZ[blk, :r], m, k, True,
                    net.bias)
                if k:   # the forward rule adds the residual to the second-order streams on the
                    # fly; the backward rule needs the complete pre-activations on the tape
                    Zt[blk, :r, 1 + m:] += hid[blk, :r, 1 + m:]
            np.matmul(flat(hid[depth], r), net.W3.T, out=flat(Y, r))
            if net.bias:
                Y[:r, 0, :] += b3
            y = Y[:r, 0, :]
            JD = np.swapaxes(Y[:r, 1:1 + m, :], 1, 2) if m else None
            if k:
                D2D = unpack_streams(Y[:r], 2, m, k)[2]
                loss, dy, dJD, dD2 = loss_fn(y, JD, D2D, slice(lo, hi))
            else:
                loss, dy, dJD = loss_fn(y, JD, slice(lo, hi))
                dD2 = None
            losses[i] = float(loss)
            Ybar = pack_cotangents(dy, dJD, m, r, o, dt, dD2, k)
            # backward
            Yb = Ybar.reshape(rows, o)
            gv["W3"] += Yb.T @ flat(hid[depth], r)
            if net.bias:
                gv["b3"] += Ybar[:, 0, :].sum(axis=0)
            np.matmul(Yb, net.W3, out=flat(hbar, r))
            for blk in range(depth - 1, -1, -1):
                # hbar: of the block's output h; zbar, abar, ubar: of its Zt, A and U
                act_back(Zt[blk, :r], SGZ[blk, :r], hbar[:r], zbar[:r], m)
                gv["W2"][blk] += flat(zbar, r).T @ flat(A[blk], r)
                if net.bias:
                    gv["b2"][blk] += zbar[:r, 0, :].sum(axis=0)
                np.matmul(flat(zbar, r), net.W2[blk], out=flat(abar, r))
                act_back(U[blk, :r], SGU[blk, :r], abar[:r], ubar[:r], m)
                gv["W1"][blk] += flat(ubar, r).T @ flat(hid[blk], r)
                if net.bias:
                    gv["b1"][blk] += ubar[:r, 0, :].sum(axis=0)
                np.matmul(flat(ubar, r), net.W1[blk], out=flat(tmp, r))
                np.add(zbar[:r], tmp[:r], out=hbar[:r])       # the residual path and the block's
            act_back(Z0[:r], SG0[:r], hbar[:r], zbar[:r], m)
            gv["W0"] += zbar[:r, 0, :].T @ x[lo:hi]
            for a in range(m):
                if Dc is None:
                    gv["W0"][:, a] += zbar[:r, 1 + a, :].sum(axis=0)
                else:
                    gv["W0"] += zbar[:r, 1 + a, :].T @ Dc[:, :, a]
            if net.bias:
                gv["b0"] += zbar[:r, 0, :].sum(axis=0)
