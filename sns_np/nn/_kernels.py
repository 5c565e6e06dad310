"""Numba kernels of the derivative engine (private).

Plain functions of arrays and scalars: no validation, no classes (the Python layer in
:mod:`sns_np.nn._engine` allocates and picks the kernel). Every kernel writes into
preallocated arrays. The fused jet rules exist twice over one row-range body
(``_softplus_jet_rows``, ``_softplus_jet_back_rows``): threaded (``prange`` over blocks of
points) for the threaded path, and serial without the GIL (``*_serial``, Python shims that
call the row kernels on the whole chunk) for the worker threads of :mod:`sns_np.nn._parallel`,
which run one whole chunk each.

First-call cost: every jitted function is compiled (or loaded from the cache) on its first
call, and a jitted wrapper around another jitted function costs a compilation of its own in
which LLVM optimises the inlined body again. So the serial entry points are Python shims, and
the scalar helpers ``_exp_parts`` and ``_softplus_sigmoid`` are inlined at the Numba IR level
(``inline="always"``) instead of compiled separately (docs/performance.md, "First call").

Stream layout
-------------
Activations of a chunk of ``c`` points are stored as ``(c, S, w)`` arrays: for each point the
value stream (index 0), then ``m`` first-order streams (derivatives along the m directions),
then the second-order streams of the pairs ``(a, b)``, ``a <= b < k``, in row-major order.
``S = 1 + m + k (k + 1) / 2``.

Transcendentals
---------------
LLVM does not vectorise calls to libm's exp and log1p, which would make the elementwise passes
cost a third of the matrix products. :func:`_exp_parts` and :func:`_softplus_sigmoid` evaluate
e = exp(-|z|) (Cody-Waite reduction, degree-12 Taylor polynomial, 2^n assembled from its bits)
and log1p(e) = 2 atanh(e / (2 + e)) (odd series) with arithmetic only, so both loops vectorise
(AVX2/AVX-512). Relative error below 1e-15 for |z| < 708; beyond, exp(-|z|) is clamped at
exp(-708) ~ 3e-308 (an absolute error below 1e-307 on softplus and sigmoid).
``error_model="numpy"`` removes Python's zero-division check, which blocks vectorisation.
Float32 streams (training) get the same formulas in float32 arithmetic with shorter
polynomials (:func:`_softplus_sigmoid32`, relative error below 3e-7): twice the lanes and
half the terms; the choice is made by type when a kernel is compiled
(:func:`_softplus_parts`). The float32 forward rule of a training step costs 45% less
(docs/performance.md).

Aliasing
--------
The row kernels accept outputs that overlap their inputs (``out`` may be ``Z``, ``Zbar`` may
be ``Abar``), but LLVM vectorises a loop only behind a run-time check that its arrays do
not overlap, and runs the scalar loop when they do: a reverse pass in place costs 3.5 times
one into a separate array. The engine therefore never passes overlapping arrays
(:mod:`sns_np.nn._engine`).
"""

from __future__ import annotations

import math
import os
import threading

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

_LOG2E = 1.4426950408889634
_LN2_HI = 0.6931471803691238
_LN2_LO = 1.9082149292705877e-10
_SHIFT = 6755399441055744.0  # 1.5 * 2**52: adding and subtracting it rounds to an integer

# the same in float32 (every literal of a float32 loop must be float32, or LLVM computes it in
# float64): Cody-Waite's two-part ln 2 for single precision, and 1.5 * 2**23
_F = np.float32
_LOG2E32, _LN2_HI32, _LN2_LO32 = _F(_LOG2E), _F(0.693359375), _F(-2.12194440e-4)
_SHIFT32 = _F(12582912.0)
_ZMIN32 = _F(-87.0)     # exp(-87) ~ 1.6e-38, the smallest normal float32 is 1.2e-38
_C2, _C3, _C4, _C5, _C6, _C7 = (_F(1 / 2), _F(1 / 6), _F(1 / 24), _F(1 / 120), _F(1 / 720),
                                _F(1 / 5040))
_L3, _L5, _L7, _L9, _L11, _L13, _L15 = (_F(1 / 3), _F(1 / 5), _F(1 / 7), _F(1 / 9),
                                        _F(1 / 11), _F(1 / 13), _F(1 / 15))
_ONE32, _TWO32, _ZERO32 = _F(1.0), _F(2.0), _F(0.0)

_JIT = dict(cache=True, fastmath={"contract"}, error_model="numpy")
_PJIT = dict(_JIT, parallel=True)
_SJIT = dict(_JIT, nogil=True)  # serial kernels that worker threads run side by side

#: point blocks per parallel kernel call: scratch is allocated once per block, and 64 blocks
#: balance any thread count up to 64
_NBLK = 64

#: softplus(z) and sigmoid(z) are flushed to 0 for z < -_FLUSH_Z (where both are below 1e-30,
#: an absolute change of less than 1e-30), and in float32 already for z < -_FLUSH_Z32 (below
#: 4.3e-18, under float32's resolution of the O(1) features beside them). Without it, the
#: hidden layers of a network with a large first-layer scale (fitting detailed meshes,
#: input_scale 40) carry float32 subnormals (below 1.2e-38, z < -87) into the matrix products,
#: which run 1.4x slower on them (docs/performance.md).
_FLUSH_Z = 69.0
_FLUSH_Z32 = 40.0

#: float32 only: first-order streams and reverse-pass cotangents below this in magnitude are
#: flushed to 0. A fit drives some units far negative; the products of their small sigmoids
#: along the layers are subnormal, and the weight-gradient products then run on them: a
#: training step of the network fitted to FLOWER took 157 ms against 68 ms for a fresh one,
#: 65 ms with the flush (docs/performance.md). A flushed cotangent contributes under 1e-15 to
#: a weight's gradient, which Adam (eps 1e-8) turns into less than 1e-7 of the rate.
_FLUSH_BAR32 = 1e-20


@njit(inline="always", **_JIT)
def _flush_z(x):
    """The z below which softplus and sigmoid are flushed, for the dtype of array x."""
    return _FLUSH_Z32 if x.itemsize == 4 else _FLUSH_Z


@njit(inline="always", **_JIT)
def _flush_bar(x):
    """The magnitude below which streams and cotangents are flushed, for x's dtype."""
    return _FLUSH_BAR32 if x.itemsize == 4 else 0.0


_start_lock = threading.Lock()
_started = False


def start_threads():
    """Start Numba's thread pool, once, with a passive OpenMP wait policy.

    Numba's OpenMP workers and OpenBLAS's threads both spin-wait after a parallel region. The
    threaded path alternates BLAS products with Numba passes dozens of times per chunk, and
    with both pools spinning on 2 cores each pass waits for the other's spinners: measured
    8.2 ms instead of 1.6 ms per product + pass. A passive OpenMP wait policy removes that.
    The OpenMP runtime reads ``OMP_WAIT_POLICY`` once, when Numba loads it to start its pool;
    so the variable is set for that moment only and removed again, and the process
    environment (which child processes inherit) is left as it was. A user's own setting wins,
    and a pool that was started before keeps whatever policy it started with. Called by the
    engine before its first threaded kernel; importing this module changes nothing.
    """
    global _started
    if _started:
        return
    import numba

    with _start_lock:
        if _started:
            return
        ours = "OMP_WAIT_POLICY" not in os.environ
        if ours:
            os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
        try:
            numba.get_num_threads()  # launches the threading layer (loads OpenMP)
        finally:
            if ours:
                os.environ.pop("OMP_WAIT_POLICY", None)
        _started = True


@njit(inline="always", **_JIT)
def _exp_parts(z, p, ib):
    """p[j] * 2^n[j] = exp(-|z[j]|): the mantissa polynomial in p, the 2^n bits in ib."""
    for j in range(z.shape[0]):
        t = max(-abs(float(z[j])), -708.0)  # float64 even for float32 z (NumPy 2 would keep
        # float32 without the JIT, and the 1.5 * 2^52 rounding trick needs float64)
        n = (t * _LOG2E + _SHIFT) - _SHIFT
        r = (t - n * _LN2_HI) - n * _LN2_LO
        p[j] = 1.0 + r * (1.0 + r * (1 / 2 + r * (1 / 6 + r * (1 / 24 + r * (
            1 / 120 + r * (1 / 720 + r * (1 / 5040 + r * (1 / 40320 + r * (
                1 / 362880 + r * (1 / 3628800 + r * (1 / 39916800 + r / 479001600)))))))))))
        ib[j] = np.int64(n + 1023.0) << 52


@njit(inline="always", **_JIT)
def _softplus_sigmoid(z, p, fb, a, sig, s2):
    """a = softplus(z), sig = sigmoid(z), s2 = sig (1 - sig), from the parts of exp(-|z|)."""
    fz = _flush_z(z)
    for j in range(z.shape[0]):
        e = p[j] * fb[j]
        u = e / (2.0 + e)
        u2 = u * u
        lg = 2.0 * u * (1.0 + u2 * (1 / 3 + u2 * (1 / 5 + u2 * (1 / 7 + u2 * (1 / 9 + u2 * (
            1 / 11 + u2 * (1 / 13 + u2 * (1 / 15 + u2 * (1 / 17 + u2 * (1 / 19 + u2 * (
                1 / 21 + u2 * (1 / 23 + u2 * (1 / 25 + u2 * (1 / 27 + u2 * (
                    1 / 29 + u2 * (1 / 31 + u2 / 33))))))))))))))))
        zj = z[j]
        q = 1.0 / (1.0 + e)
        sj = q * (e if zj < 0.0 else 1.0)
        aj = max(zj, 0.0) + lg
        if zj < -fz:            # flushed, see _FLUSH_Z
            sj = 0.0
            aj = 0.0
        a[j] = aj
        sig[j] = sj
        s2[j] = sj * (1.0 - sj)


@njit(inline="always", **_JIT)
def _softplus_sigmoid32(z, p, ib, a, sig, s2):
    """:func:`_exp_parts` and :func:`_softplus_sigmoid` in float32 arithmetic, for float32 z:
    a degree-7 polynomial for exp(-|z|) and eight terms of the odd series for log1p, enough
    for float32 (relative error below 3e-7, a few units in the last place). ``ib`` is
    int64 scratch of z's length, used as int32 bits."""
    fz = -_F(_FLUSH_Z32)
    bits = ib.view(np.int32)
    fb = ib.view(np.float32)
    for j in range(z.shape[0]):
        t = max(-abs(z[j]), _ZMIN32)
        n = (t * _LOG2E32 + _SHIFT32) - _SHIFT32
        r = (t - n * _LN2_HI32) - n * _LN2_LO32
        p[j] = _ONE32 + r * (_ONE32 + r * (_C2 + r * (_C3 + r * (_C4 + r * (
            _C5 + r * (_C6 + r * _C7))))))
        bits[j] = (np.int32(n) + np.int32(127)) << 23
    for j in range(z.shape[0]):
        e = p[j] * fb[j]
        u = e / (_TWO32 + e)
        u2 = u * u
        lg = _TWO32 * u * (_ONE32 + u2 * (_L3 + u2 * (_L5 + u2 * (_L7 + u2 * (_L9 + u2 * (
            _L11 + u2 * (_L13 + u2 * _L15)))))))
        zj = z[j]
        q = _ONE32 / (_ONE32 + e)
        sj = q * (e if zj < _ZERO32 else _ONE32)
        aj = max(zj, _ZERO32) + lg
        if zj < fz:             # flushed, see _FLUSH_Z
            sj = _ZERO32
            aj = _ZERO32
        a[j] = aj
        sig[j] = sj
        s2[j] = sj * (_ONE32 - sj)


def _softplus_parts(z, p, ib, a, sig, s2):
    """a = softplus(z), sig = sigmoid(z), s2 = sig (1 - sig) for a row z, in z's precision.

    Compiled, the choice between the float64 and float32 arithmetic is made by type, when
    the kernel is compiled (the overload below); this body runs only without the JIT.
    ``p`` is scratch of z's dtype, ``ib`` int64 scratch, both of z's length.
    """
    if z.dtype == np.float32:
        _softplus_sigmoid32(z, p, ib, a, sig, s2)
    else:
        _exp_parts(z, p, ib)
        _softplus_sigmoid(z, p, ib.view(np.float64), a, sig, s2)


@overload(_softplus_parts, inline="always")
def _softplus_parts_typed(z, p, ib, a, sig, s2):
    if z.dtype == types.float32:
        def single(z, p, ib, a, sig, s2):
            _softplus_sigmoid32(z, p, ib, a, sig, s2)
        return single

    def double(z, p, ib, a, sig, s2):
        _exp_parts(z, p, ib)
        _softplus_sigmoid(z, p, ib.view(np.float64), a, sig, s2)
    return double


@njit(**_PJIT)
def softplus_values(z, out):
    """out = softplus(z) for a 2-D array (a convenience for tests and order-0 passes)."""
    c, w = z.shape
    for i in prange(c):
        p = np.empty(w)
        ib = np.empty(w, np.int64)
        sig = np.empty(w)
        s2 = np.empty(w)
        zi = np.empty(w, z.dtype)
        for j in range(w):
            zi[j] = z[i, j]
        _exp_parts(zi, p, ib)
        a = np.empty(w)
        _softplus_sigmoid(zi, p, ib.view(np.float64), a, sig, s2)
        for j in range(w):
            out[i, j] = a[j]


@njit(**_SJIT)
def _softplus_jet_rows(Z, R, bias, out, sig, m, k, has_res, has_bias, lo, hi):
    """The fused forward jet rule of softplus on the points lo..hi-1 of a chunk.

    Z : (c, S, w) pre-activation streams. With ``has_res`` the residual input R (c, S, w) is
        added, and with ``has_bias`` the bias (w,) is added to the value stream. The complete
        value and first-order pre-activations are written back into Z (the tape of the
        first-order backward pass); the second-order ones are consumed on the fly.
    out : (c, S, w) activation streams (may be Z itself, or R).
    sig : (c, w) receives s'(z) = sigmoid of the value stream.

    a = s(z);  a_a = s'(z) z_a;  a_ab = s''(z) z_a z_b + s'(z) z_ab
    """
    w = Z.shape[2]
    p = np.empty(w, Z.dtype)
    ib = np.empty(w, np.int64)
    s1 = np.empty(w, Z.dtype)
    s2 = np.empty(w, Z.dtype)
    a0 = np.empty(w, Z.dtype)
    fb_ = _flush_bar(out)
    for i in range(lo, hi):
        if has_res:
            for s in range(1 + m):
                for j in range(w):
                    Z[i, s, j] += R[i, s, j]
        if has_bias:
            for j in range(w):
                Z[i, 0, j] += bias[j]
        _softplus_parts(Z[i, 0], p, ib, a0, s1, s2)
        q = 1 + m
        for a in range(k):
            for b in range(a, k):
                if has_res:
                    for j in range(w):
                        out[i, q, j] = (s2[j] * Z[i, 1 + a, j] * Z[i, 1 + b, j]
                                        + s1[j] * (Z[i, q, j] + R[i, q, j]))
                else:
                    for j in range(w):
                        out[i, q, j] = (s2[j] * Z[i, 1 + a, j] * Z[i, 1 + b, j]
                                        + s1[j] * Z[i, q, j])
                q += 1
        for a in range(m):
            for j in range(w):
                d = s1[j] * Z[i, 1 + a, j]
                out[i, 1 + a, j] = 0.0 if abs(d) < fb_ else d     # NaN kept
        for j in range(w):
            out[i, 0, j] = a0[j]
            sig[i, j] = s1[j]


@njit(**_PJIT)
def softplus_jet(Z, R, bias, out, sig, m, k, has_res, has_bias):
    """:func:`_softplus_jet_rows` on a whole chunk, its points split over Numba's threads."""
    c = Z.shape[0]
    nblk = min(c, _NBLK)
    for t in prange(nblk):
        _softplus_jet_rows(Z, R, bias, out, sig, m, k, has_res, has_bias,
                           (c * t) // nblk, (c * (t + 1)) // nblk)


def softplus_jet_serial(Z, R, bias, out, sig, m, k, has_res, has_bias):
    """:func:`_softplus_jet_rows` on a whole chunk in the calling thread, without the GIL.

    A Python shim, not a kernel of its own: a jitted wrapper would be one more compilation
    (LLVM optimises the inlined rows body again), 0.3-0.5 s of the first call (First call,
    docs/performance.md).
    """
    _softplus_jet_rows(Z, R, bias, out, sig, m, k, has_res, has_bias, 0, Z.shape[0])


@njit(**_SJIT)
def _softplus_jet_back_rows(Z, sig, Abar, Zbar, m, lo, hi):
    """Reverse of the first-order jet rule (value and m first-order streams), points lo..hi-1.

    Given cotangents Abar (c, 1+m, w) of a = s(z), a_a = s'(z) z_a, write into Zbar (may alias
    Abar) the cotangents of the pre-activation streams:

        zbar_a = s'(z) abar_a
        zbar   = s'(z) abar + s''(z) sum_a abar_a z_a
    """
    w = Z.shape[2]
    acc = np.empty(w)
    fb_ = _flush_bar(Zbar)
    for i in range(lo, hi):
        acc[:] = 0.0
        for a in range(m):
            for j in range(w):
                g = Abar[i, 1 + a, j]
                acc[j] += g * Z[i, 1 + a, j]
                zb = sig[i, j] * g
                Zbar[i, 1 + a, j] = 0.0 if abs(zb) < fb_ else zb   # NaN kept
        for j in range(w):
            s = sig[i, j]
            zb = s * Abar[i, 0, j] + s * (1.0 - s) * acc[j]
            Zbar[i, 0, j] = 0.0 if abs(zb) < fb_ else zb


@njit(**_PJIT)
def softplus_jet_back(Z, sig, Abar, Zbar, m):
    """:func:`_softplus_jet_back_rows` on a whole chunk, split over Numba's threads."""
    c = Z.shape[0]
    nblk = min(c, _NBLK)
    for t in prange(nblk):
        _softplus_jet_back_rows(Z, sig, Abar, Zbar, m, (c * t) // nblk, (c * (t + 1)) // nblk)


def softplus_jet_back_serial(Z, sig, Abar, Zbar, m):
    """:func:`_softplus_jet_back_rows` on a whole chunk in the calling thread, without the GIL
    (a Python shim, as :func:`softplus_jet_serial`)."""
    _softplus_jet_back_rows(Z, sig, Abar, Zbar, m, 0, Z.shape[0])


@njit(**_SJIT)
def _softplus_jet2_back_rows(Z, sig, Abar, Zbar, m, k, lo, hi):
    """Reverse of the second-order jet rule (all S = 1 + m + k (k + 1) / 2 streams), points
    lo..hi-1: the training step of a loss on second derivatives.

    Z holds the complete pre-activation streams (value, first and second order); given the
    cotangents Abar (c, S, w) of a = s(z), a_a = s'(z) z_a, a_ab = s''(z) z_a z_b + s'(z) z_ab,
    write into Zbar (may alias Abar) the cotangents of the pre-activation streams:

        zbar_ab = s'(z) abar_ab
        zbar_a  = s'(z) abar_a + s''(z) sum_(pairs ab) abar_ab z_b      (z_a for b's)
        zbar    = s'(z) abar + s''(z) sum_a abar_a z_a
                  + sum_(pairs ab) abar_ab (s3(z) z_a z_b + s''(z) z_ab)

    with s' = sigmoid, s'' = s' (1 - s'), s3 = s'' (1 - 2 s') the third derivative. A stored
    pair (a, b), a < b, stands for both orders, as in the forward rule; a pair (a, a) gives
    2 s'' abar_aa z_a.
    """
    w = Z.shape[2]
    acc = np.empty(w)
    accd = np.empty((max(m, 1), w))
    fb_ = _flush_bar(Zbar)
    for i in range(lo, hi):
        acc[:] = 0.0
        accd[:] = 0.0
        q = 1 + m
        for a in range(k):
            for b in range(a, k):
                for j in range(w):
                    s = sig[i, j]
                    s2 = s * (1.0 - s)
                    g = Abar[i, q, j]
                    za = Z[i, 1 + a, j]
                    zb = Z[i, 1 + b, j]
                    acc[j] += g * (s2 * (1.0 - 2.0 * s) * za * zb + s2 * Z[i, q, j])
                    accd[a, j] += s2 * g * zb
                    accd[b, j] += s2 * g * za
                    d = s * g
                    Zbar[i, q, j] = 0.0 if abs(d) < fb_ else d     # NaN kept
                q += 1
        for a in range(m):
            for j in range(w):
                s = sig[i, j]
                g = Abar[i, 1 + a, j]
                acc[j] += s * (1.0 - s) * g * Z[i, 1 + a, j]
                d = s * g + accd[a, j]
                Zbar[i, 1 + a, j] = 0.0 if abs(d) < fb_ else d
        for j in range(w):
            d = sig[i, j] * Abar[i, 0, j] + acc[j]
            Zbar[i, 0, j] = 0.0 if abs(d) < fb_ else d


@njit(**_PJIT)
def softplus_jet2_back(Z, sig, Abar, Zbar, m, k):
    """:func:`_softplus_jet2_back_rows` on a whole chunk, split over Numba's threads."""
    c = Z.shape[0]
    nblk = min(c, _NBLK)
    for t in prange(nblk):
        _softplus_jet2_back_rows(Z, sig, Abar, Zbar, m, k, (c * t) // nblk,
                                 (c * (t + 1)) // nblk)


def softplus_jet2_back_serial(Z, sig, Abar, Zbar, m, k):
    """:func:`_softplus_jet2_back_rows` on a whole chunk in the calling thread, without the
    GIL (a Python shim, as :func:`softplus_jet_serial`)."""
    _softplus_jet2_back_rows(Z, sig, Abar, Zbar, m, k, 0, Z.shape[0])


# ---------------------------------------------------------------------------------------------
# Small networks (width <= 32): one point per iteration, every layer in registers and L1.
# BLAS call overhead dominates at these sizes, so the whole jet is one kernel.
# ---------------------------------------------------------------------------------------------


@njit(**_JIT)
def _small_act(z, out, sig, s2, m, k):
    """In-register jet rule for one point: z, out (S, w); sig, s2 (w,) scratch outputs."""
    S, w = z.shape
    p = np.empty(w)
    ib = np.empty(w, np.int64)
    a0 = np.empty(w)
    _exp_parts(z[0], p, ib)
    _softplus_sigmoid(z[0], p, ib.view(np.float64), a0, sig, s2)
    q = 1 + m
    for a in range(k):
        for b in range(a, k):
            for j in range(w):
                out[q, j] = s2[j] * z[1 + a, j] * z[1 + b, j] + sig[j] * z[q, j]
            q += 1
    for a in range(m):
        for j in range(w):
            out[1 + a, j] = sig[j] * z[1 + a, j]
    for j in range(w):
        out[0, j] = a0[j]


@njit(**_JIT)
def _small_linear(A, W, b, out, has_bias):
    """out[s] = W @ A[s] for every stream s (+ b on the value stream)."""
    S, n_in = A.shape
    n_out = W.shape[0]
    for s in range(S):
        for r in range(n_out):
            acc = 0.0
            for j in range(n_in):
                acc += W[r, j] * A[s, j]
            out[s, r] = acc
    if has_bias:
        for r in range(n_out):
            out[0, r] += b[r]


@njit(**_PJIT)
def small_forward(x, D, W0, b0, W1, b1, W2, b2, W3, b3, has_bias, m, k, Y):
    """Forward jets of a small residual MLP, one point per iteration.

    x : (n, d) inputs; D : (n, d, m) directions; Y : (n, S, o) output streams.
    """
    n, d = x.shape
    w = W0.shape[0]
    depth = W1.shape[0]
    S = Y.shape[1]
    for i in prange(n):
        z = np.zeros((S, w))
        h = np.empty((S, w))
        a = np.empty((S, w))
        u = np.empty((S, w))
        sig = np.empty(w)
        s2 = np.empty(w)
        for r in range(w):
            acc = 0.0
            for j in range(d):
                acc += W0[r, j] * x[i, j]
            z[0, r] = acc + (b0[r] if has_bias else 0.0)
            for c in range(m):
                acc = 0.0
                for j in range(d):
                    acc += W0[r, j] * D[i, j, c]
                z[1 + c, r] = acc
        _small_act(z, h, sig, s2, m, k)
        for blk in range(depth):
            _small_linear(h, W1[blk], b1[blk], u, has_bias)
            _small_act(u, a, sig, s2, m, k)
            _small_linear(a, W2[blk], b2[blk], z, has_bias)
            for s in range(S):
                for j in range(w):
                    z[s, j] += h[s, j]
            _small_act(z, h, sig, s2, m, k)
        _small_linear(h, W3, b3, Y[i], has_bias)


@njit(**_JIT)
def _small_act_back(z, sig, abar, zbar, m):
    """Reverse of the first-order jet rule for one point (zbar may alias abar)."""
    w = z.shape[1]
    for j in range(w):
        acc = 0.0
        for a in range(m):
            g = abar[1 + a, j]
            acc += g * z[1 + a, j]
            zbar[1 + a, j] = sig[j] * g
        s = sig[j]
        zbar[0, j] = s * abar[0, j] + s * (1.0 - s) * acc


@njit(**_JIT)
def _small_linear_back(Zbar, A, W, gW, gb, Abar, has_bias, accumulate_input):
    """Reverse of out[s] = W A[s] (+ b): gW += sum_s Zbar[s] A[s]^T, gb += Zbar[0],
    Abar[s] (+)= W^T Zbar[s]."""
    S, n_out = Zbar.shape
    n_in = A.shape[1]
    for s in range(S):
        for r in range(n_out):
            g = Zbar[s, r]
            for j in range(n_in):
                gW[r, j] += g * A[s, j]
    if has_bias:
        for r in range(n_out):
            gb[r] += Zbar[0, r]
    for s in range(S):
        for j in range(n_in):
            acc = 0.0
            for r in range(n_out):
                acc += W[r, j] * Zbar[s, r]
            if accumulate_input:
                Abar[s, j] += acc
            else:
                Abar[s, j] = acc


@njit(**_PJIT)
def small_vjp(x, D, W0, b0, W1, b1, W2, b2, W3, b3, has_bias, m, Ybar,
              gW0, gb0, gW1, gb1, gW2, gb2, gW3, gb3):
    """Parameter gradient of sum(Ybar * Y) for first-order streams Y (n, 1+m, o).

    The gradient arrays carry a leading thread-block axis (nblk, ...): block t accumulates the
    points of its own slice, the caller sums over blocks (deterministic for a fixed nblk).
    """
    n, d = x.shape
    w = W0.shape[0]
    depth = W1.shape[0]
    S = 1 + m
    nblk = gW0.shape[0]
    for t in prange(nblk):
        lo = (n * t) // nblk
        hi = (n * (t + 1)) // nblk
        # tape: block inputs hid, inner pre-activations u, inner activations a, outer pre-acts z
        hid = np.empty((depth + 1, S, w))
        U = np.empty((depth, S, w))
        A = np.empty((depth, S, w))
        Zt = np.empty((depth, S, w))
        Z0 = np.zeros((S, w))
        SG0 = np.empty(w)
        SGU = np.empty((depth, w))
        SGZ = np.empty((depth, w))
        s2 = np.empty(w)
        hbar = np.empty((S, w))
        abar = np.empty((S, w))
        for i in range(lo, hi):
            for r in range(w):
                acc = 0.0
                for j in range(d):
                    acc += W0[r, j] * x[i, j]
                Z0[0, r] = acc + (b0[r] if has_bias else 0.0)
                for c in range(m):
                    acc = 0.0
                    for j in range(d):
                        acc += W0[r, j] * D[i, j, c]
                    Z0[1 + c, r] = acc
            _small_act(Z0, hid[0], SG0, s2, m, 0)
            for blk in range(depth):
                _small_linear(hid[blk], W1[blk], b1[blk], U[blk], has_bias)
                _small_act(U[blk], A[blk], SGU[blk], s2, m, 0)
                _small_linear(A[blk], W2[blk], b2[blk], Zt[blk], has_bias)
                for s in range(S):
                    for j in range(w):
                        Zt[blk, s, j] += hid[blk, s, j]
                _small_act(Zt[blk], hid[blk + 1], SGZ[blk], s2, m, 0)
            # backward
            _small_linear_back(Ybar[i], hid[depth], W3, gW3[t], gb3[t], hbar, has_bias, False)
            for blk in range(depth - 1, -1, -1):
                _small_act_back(Zt[blk], SGZ[blk], hbar, hbar, m)       # hbar := zbar
                _small_linear_back(hbar, A[blk], W2[blk], gW2[t, blk], gb2[t, blk], abar,
                                   has_bias, False)
                _small_act_back(U[blk], SGU[blk], abar, abar, m)        # abar := ubar
                # residual: hbar (= zbar) keeps flowing, plus W1^T ubar
                _small_linear_back(abar, hid[blk], W1[blk], gW1[t, blk], gb1[t, blk], hbar,
                                   has_bias, True)
            _small_act_back(Z0, SG0, hbar, hbar, m)
            for s in range(S):
                for r in range(w):
                    g = hbar[s, r]
                    if s == 0:
                        if has_bias:
                            gb0[t, r] += g
                        for j in range(d):
                            gW0[t, r, j] += g * x[i, j]
                    else:
                        for j in range(d):
                            gW0[t, r, j] += g * D[i, j, s - 1]


# ---------------------------------------------------------------------------------------------
# Optimiser update
# ---------------------------------------------------------------------------------------------

@njit(**_PJIT)
def adam_update(theta, g, m, v, lr_hat, b1, b2, vhat_scale, eps):
    """One fused Adam update in place (:class:`sns_np.nn.optim.Adam`), one pass over memory:

        m = b1 m + (1 - b1) g;   v = b2 v + (1 - b2) g^2
        theta -= lr_hat m / (sqrt(v vhat_scale) + eps)

    in float64 arithmetic, stored in the arrays' dtype. In float32, moments below float32's
    smallest normal number are stored as 0: weights whose gradient has died out would
    otherwise carry subnormal moments, on which every later update runs several times slower
    (their update is below 1e-30 of the rate either way).
    """
    n = theta.shape[0]
    tiny = 1.1754943508222875e-38 if theta.itemsize == 4 else 0.0
    nblk = min(n, _NBLK)
    for t in prange(nblk):
        for i in range((n * t) // nblk, (n * (t + 1)) // nblk):
            gi = float(g[i])
            mi = b1 * m[i] + (1.0 - b1) * gi
            vi = b2 * v[i] + (1.0 - b2) * (gi * gi)
            if abs(mi) < tiny:
                mi = 0.0
            if vi < tiny:
                vi = 0.0
            m[i] = mi
            v[i] = vi
            theta[i] -= lr_hat * mi / (math.sqrt(vi * vhat_scale) + eps)
