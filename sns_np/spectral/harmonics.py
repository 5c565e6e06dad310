"""Real spherical harmonics up to degree L with exact ambient jets, and fields built from them.

The basis of the Rayleigh-Ritz method (:mod:`sns_np.spectral.ritz`). ``Y_lm`` is the real,
orthonormal harmonic without the Condon-Shortley phase (the convention of
:class:`sns_np.shapes.SphericalHarmonic`)::

    Y_l0 = A_l^0,   Y_lm = sqrt(2) A_l^m Re (x + i y)^m,   Y_l,-m = sqrt(2) A_l^m Im (x + i y)^m,

extended off the sphere as the **solid harmonic** ``r^l Y_lm(x / r)``, a homogeneous harmonic
polynomial, so value, gradient and Hessian are exact in R^3. ``A_l^m(z, rho)`` (``rho =
|x|^2``) is the normalised associated Legendre polynomial divided by ``sin^m theta``, from the
stable three-term recurrence (Holmes & Featherstone 2002, written for solid harmonics)::

    A_m^m = sqrt((2m+1) / 4 pi) prod_{k<=m} sqrt((2k-1) / 2k)
    A_l^m = a_lm z A_{l-1}^m - b_lm rho A_{l-2}^m,
    a_lm = sqrt((4l^2 - 1) / (l^2 - m^2)),
    b_lm = sqrt(((l-1)^2 - m^2) (2l+1) / ((2l-3) (l^2 - m^2))),

with the derivatives in ``z`` and ``rho`` carried through the same recurrence. Nothing
overflows for large degrees (``A_m^m`` grows like ``m^(1/4)``). The index of ``Y_lm`` is
``l^2 + l + m``.

References
----------
S. A. Holmes and W. E. Featherstone, "A unified approach to the Clenshaw summation and the
recursive computation of very high degree and order normalised associated Legendre
functions", Journal of Geodesy 76, 2002.
"""

from __future__ import annotations

import math

import numpy as np

from .._validation import as_points, check_order, check_positive_int
from ..errors import ShapeError

__all__ = ["sh_index", "n_harmonics", "real_sh", "HarmonicField"]


def sh_index(l: int, m: int) -> int:
    """Column of ``Y_lm`` in :func:`real_sh`: ``l^2 + l + m``.

    Examples
    --------
    >>> sh_index(0, 0), sh_index(1, -1), sh_index(1, 1), sh_index(2, 0)
    (0, 1, 3, 6)
    """
    return l * l + l + m


def n_harmonics(L: int) -> int:
    """Number of harmonics of degree ``<= L``: ``(L + 1)^2``.

    Examples
    --------
    >>> n_harmonics(2), real_sh(np.array([[0.0, 0.0, 1.0]]), 2).shape
    (9, (1, 9))
    """
    return (L + 1) ** 2


def _powers(x, y, L, order):
    """Re/Im of (x + i y)^m for m = 0..L, each a tuple (value, grad (n,3), hess (n,3,3))."""
    n = x.shape[0]
    C = [np.ones(n)]
    S = [np.zeros(n)]
    for _ in range(L):
        C.append(C[-1] * x - S[-1] * y)
        S.append(C[-2] * y + S[-1] * x)
    out = []
    for m in range(L + 1):
        if order == 0:
            out.append(((C[m], None, None), (S[m], None, None)))
            continue
        gC, gS = np.zeros((n, 3)), np.zeros((n, 3))
        if m >= 1:  # d/dx z^m = m z^(m-1), d/dy z^m = i m z^(m-1)
            gC[:, 0], gC[:, 1] = m * C[m - 1], -m * S[m - 1]
            gS[:, 0], gS[:, 1] = m * S[m - 1], m * C[m - 1]
        hC = hS = None
        if order == 2:
            hC, hS = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
            if m >= 2:  # d2/dx2 = m(m-1) z^(m-2), d2/dxdy = i (.), d2/dy2 = -(.)
                c, s = m * (m - 1) * C[m - 2], m * (m - 1) * S[m - 2]
                hC[:, 0, 0], hC[:, 1, 1], hC[:, 0, 1] = c, -c, -s
                hS[:, 0, 0], hS[:, 1, 1], hS[:, 0, 1] = s, -s, c
                hC[:, 1, 0], hS[:, 1, 0] = hC[:, 0, 1], hS[:, 0, 1]
        out.append(((C[m], gC, hC), (S[m], gS, hS)))
    return out


def _product(A, dA, D2A, P, order):
    """Jets of ``F = A(z, rho) * P(x, y)`` from A's partials and P's ambient jets."""
    a, p = A[0], P[0]
    F = a * p
    if order == 0:
        return F, None, None
    grad = p[:, None] * dA + a[:, None] * P[1]
    if order == 1:
        return F, grad, None
    D2 = (p[:, None, None] * D2A + a[:, None, None] * P[2]
          + dA[:, :, None] * P[1][:, None, :] + P[1][:, :, None] * dA[:, None, :])
    return F, grad, D2


def _iterate(X, L, order):
    """Yield ``(index, value, gradient, Hessian)`` of every solid harmonic of degree <= L."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    n = X.shape[0]
    rho = np.einsum("ki,ki->k", X, X)
    ez = np.zeros((n, 3))
    ez[:, 2] = 1.0
    drho = 2.0 * X
    eye = np.eye(3)
    powers = _powers(x, y, L, order)
    amm = math.sqrt(1.0 / (4.0 * math.pi))
    for m in range(L + 1):
        if m > 0:
            amm *= math.sqrt((2 * m + 1) / (2.0 * m))
        # partials of A in (z, rho): value, z, rho, zz, zrho, rhorho
        prev = [np.zeros(n)] * 6
        cur = [np.full(n, amm)] + [np.zeros(n)] * 5
        for l in range(m, L + 1):
            if l > m:
                a = math.sqrt((4.0 * l * l - 1.0) / (l * l - m * m))
                b = (math.sqrt(((l - 1.0) ** 2 - m * m) * (2 * l + 1) / ((2 * l - 3) *
                                                                          (l * l - m * m)))
                     if l >= m + 2 else 0.0)
                v, vz, vr, vzz, vzr, vrr = cur
                w, wz, wr, wzz, wzr, wrr = prev
                nxt = [a * z * v - b * rho * w]
                if order >= 1:
                    nxt += [a * (v + z * vz) - b * rho * wz, a * z * vr - b * (w + rho * wr)]
                if order == 2:
                    nxt += [a * (2 * vz + z * vzz) - b * rho * wzz,
                            a * (vr + z * vzr) - b * (wz + rho * wzr),
                            a * z * vrr - b * (2 * wr + rho * wrr)]
                nxt += [np.zeros(n)] * (6 - len(nxt))
                prev, cur = cur, nxt
            A = cur
            dA = D2A = None
            if order >= 1:
                dA = A[1][:, None] * ez + A[2][:, None] * drho
            if order == 2:
                D2A = (A[3][:, None, None] * (ez[:, :, None] * ez[:, None, :])
                       + A[4][:, None, None] * (ez[:, :, None] * drho[:, None, :]
                                                + drho[:, :, None] * ez[:, None, :])
                       + A[5][:, None, None] * (drho[:, :, None] * drho[:, None, :])
                       + 2.0 * A[2][:, None, None] * eye)
            Pc, Ps = powers[m]
            s = math.sqrt(2.0) if m > 0 else 1.0
            F, G, D2 = _product(A, dA, D2A, Pc, order)
            yield sh_index(l, m), s * F, None if G is None else s * G, None if D2 is None \
                else s * D2
            if m > 0:
                F, G, D2 = _product(A, dA, D2A, Ps, order)
                yield sh_index(l, -m), s * F, None if G is None else s * G, None if D2 is None \
                    else s * D2


def real_sh(x, L: int, order: int = 0):
    """All real solid harmonics of degree ``<= L`` and their ambient derivatives.

    Parameters
    ----------
    x : (n, 3) float array (on the unit sphere they are the spherical harmonics)
    L : int >= 0, maximum degree
    order : int, 0, 1 or 2

    Returns
    -------
    Y : (n, (L+1)^2) float array, column ``l^2 + l + m`` holds ``Y_lm``
    G : (n, (L+1)^2, 3) float array, gradients (order >= 1)
    H : (n, (L+1)^2, 3, 3) float array, Hessians (order 2)

    Examples
    --------
    >>> Y = real_sh(np.array([[0.0, 0.0, 1.0]]), 1)
    >>> bool(np.allclose(Y, [[1 / np.sqrt(4 * np.pi), 0, np.sqrt(3 / (4 * np.pi)), 0]]))
    True
    """
    X = as_points(x, "x")
    L = check_positive_int(L, "L", minimum=0)
    order = check_order(order)
    n, nb = X.shape[0], n_harmonics(L)
    Y = np.empty((n, nb))
    G = np.empty((n, nb, 3)) if order >= 1 else None
    D2 = np.empty((n, nb, 3, 3)) if order == 2 else None
    for j, F, dF, D2F in _iterate(X, L, order):
        Y[:, j] = F
        if order >= 1:
            G[:, j] = dF
        if order == 2:
            D2[:, j] = D2F
    return Y if order == 0 else ((Y, G) if order == 1 else (Y, G, D2))


class HarmonicField:
    """``g = sum_j c_j Y_j``: a finite spherical-harmonic expansion as a field with exact jets.

    The Rayleigh-Ritz eigenfunctions are such fields. Off the sphere the field is the
    corresponding combination of solid harmonics (a polynomial), so ``jet`` is exact in R^3.

    Parameters
    ----------
    coefficients : ((L+1)^2,) float array, in the order of :func:`real_sh`
    name : str, optional label (e.g. ``"mode 3"``)

    Examples
    --------
    >>> c = np.zeros(4); c[2] = np.sqrt(4 * np.pi / 3)     # the field z
    >>> f = HarmonicField(c)
    >>> f.L, round(float(f(np.array([[0.6, 0.0, 0.8]]))[0]), 12)
    (1, 0.8)
    """

    def __init__(self, coefficients, name: str = ""):
        c = np.asarray(coefficients, dtype=np.float64)
        L = int(round(math.sqrt(c.size))) - 1 if c.ndim == 1 else -1
        if c.ndim != 1 or c.size == 0 or n_harmonics(L) != c.size:
            raise ShapeError(f"coefficients must be a vector of length (L+1)^2, got shape "
                             f"{c.shape}")
        if not np.all(np.isfinite(c)):
            raise ShapeError("coefficients contain non-finite values")
        self.coefficients, self.L, self.name = c, L, str(name)

    def jet(self, x, order: int = 0):
        """Value (n,), gradient (n, 3) and Hessian (n, 3, 3) at ``x`` (n, 3).

        Examples
        --------
        >>> from sns_np.testing import check_jet
        >>> f = HarmonicField(np.random.default_rng(0).standard_normal(9))     # degree <= 2
        >>> bool(max(check_jet(f, np.array([[0.6, 0.0, 0.8]])).values()) < 1e-7)
        True
        """
        out = evaluate_expansions(x, self.coefficients[:, None], order)
        if order == 0:
            return out[:, 0]
        return tuple(a[:, 0] for a in out)

    def __call__(self, x) -> np.ndarray:
        """The value at ``x`` (n, 3), (n,).

        Examples
        --------
        >>> f = HarmonicField(np.r_[np.sqrt(4 * np.pi), 0.0, 0.0, 0.0])   # the constant 1
        >>> f(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])), f.value(np.array([[0.0, 1.0, 0.0]]))
        (array([1., 1.]), array([1.]))
        """
        return self.jet(x, 0)

    value = __call__

    def __repr__(self):
        label = f"{self.name!r}, " if self.name else ""
        return f"HarmonicField({label}L={self.L})"


def evaluate_expansions(x, C, order: int = 0, chunk: int = 8192):
    """Values (and jets) of several expansions ``C`` ((L+1)^2, q) at once.

    Returns (n, q), and with order >= 1 also (n, q, 3) and (n, q, 3, 3); memory is bounded by
    processing ``chunk`` points at a time.
    """
    X = as_points(x, "x")
    order = check_order(order)
    C = np.asarray(C, dtype=np.float64)
    L = int(round(math.sqrt(C.shape[0]))) - 1
    n, q = X.shape[0], C.shape[1]
    V = np.zeros((n, q))
    G = np.zeros((n, q, 3)) if order >= 1 else None
    D2 = np.zeros((n, q, 3, 3)) if order == 2 else None
    for lo in range(0, n, chunk):
        sl = slice(lo, min(lo + chunk, n))
        for j, F, dF, D2F in _iterate(X[sl], L, order):
            c = C[j]
            if not c.any():
                continue
            V[sl] += F[:, None] * c
            if order >= 1:
                G[sl] += dF[:, None, :] * c[:, None]
            if order == 2:
                D2[sl] += D2F[:, None, :, :] * c[:, None, None]
    return V if order == 0 else ((V, G) if order == 1 else (V, G, D2))
