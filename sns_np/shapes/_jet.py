"""Second-order Taylor arithmetic (private): value, gradient and Hessian carried together.

A :class:`Jet` is a scalar function of ``x`` in R^3 known at n points to second order:
``v`` (n,), ``g`` (n, 3) and ``h`` (n, 3, 3). Arithmetic and the elementary functions below
propagate all three by the chain rule, so an analytic shape or field is written once as a
plain formula and its exact ambient derivatives come out with it:

    f(u):     v = f(u),  g = f'(u) u_g,  h = f''(u) u_g u_g^T + f'(u) u_h
    f(a, b):  h = f_aa a_g a_g^T + f_ab (a_g b_g^T + b_g a_g^T) + f_bb b_g b_g^T
                  + f_a a_h + f_b b_h

Each rule is one line next to its primitive. Orders below 2 are honoured (``g`` or ``h`` is
``None``) so that value-only evaluations cost nothing extra.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Jet", "sin", "cos", "sqrt", "atan2"]


def _col(c, ndim):
    """Broadcast a scalar or (n,) coefficient against an (n, ...) array of ``ndim`` dims."""
    c = np.asarray(c, dtype=np.float64)
    return c.reshape(c.shape + (1,) * (ndim - 1)) if c.ndim == 1 else c


def _outer(a, b):
    return a[:, :, None] * b[:, None, :]


class Jet:
    """Value ``v`` (n,), gradient ``g`` (n, 3) or None, Hessian ``h`` (n, 3, 3) or None."""

    __slots__ = ("v", "g", "h")
    __array_priority__ = 1000  # ndarray (op) Jet defers to Jet's reflected operators

    def __init__(self, v, g=None, h=None):
        self.v, self.g, self.h = v, g, h

    @classmethod
    def coordinates(cls, x, order):
        """The three coordinate functions ``x_a`` as jets of ``order`` at the points ``x``."""
        n = x.shape[0]
        out = []
        for a in range(3):
            g = h = None
            if order >= 1:
                g = np.zeros((n, 3))
                g[:, a] = 1.0
            if order >= 2:
                h = np.zeros((n, 3, 3))
            out.append(cls(x[:, a].copy(), g, h))
        return tuple(out)

    def apply(self, f0, f1, f2):
        """Chain rule for a scalar function with value ``f0``, slopes ``f1``, ``f2`` at ``v``."""
        g = h = None
        if self.g is not None:
            g = _col(f1, 2) * self.g
        if self.h is not None:
            h = _col(f2, 3) * _outer(self.g, self.g) + _col(f1, 3) * self.h
        return Jet(f0, g, h)

    # --- linear operations -------------------------------------------------------------
    def __add__(self, other):
        if isinstance(other, Jet):
            g = None if self.g is None or other.g is None else self.g + other.g
            h = None if self.h is None or other.h is None else self.h + other.h
            return Jet(self.v + other.v, g, h)
        return Jet(self.v + other, self.g, self.h)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.v, None if self.g is None else -self.g,
                   None if self.h is None else -self.h)

    def __sub__(self, other):
        return self + (-other)

    def __rsub__(self, other):
        return (-self) + other

    # --- products ------------------------------------------------------------------------
    def __mul__(self, other):
        if not isinstance(other, Jet):
            return Jet(self.v * other,
                       None if self.g is None else _col(other, 2) * self.g,
                       None if self.h is None else _col(other, 3) * self.h)
        a, b = self, other
        g = h = None
        if a.g is not None and b.g is not None:
            g = _col(b.v, 2) * a.g + _col(a.v, 2) * b.g
        if a.h is not None and b.h is not None:
            h = (_col(b.v, 3) * a.h + _col(a.v, 3) * b.h
                 + _outer(a.g, b.g) + _outer(b.g, a.g))
        return Jet(a.v * b.v, g, h)

    __rmul__ = __mul__

    def reciprocal(self):
        v = self.v
        return self.apply(1.0 / v, -1.0 / v**2, 2.0 / v**3)

    def __truediv__(self, other):
        if isinstance(other, Jet):
            return self * other.reciprocal()
        return self * (1.0 / np.asarray(other, dtype=np.float64))

    def __rtruediv__(self, other):
        return self.reciprocal() * other

    def __pow__(self, k):
        if not isinstance(k, int) or k < 0:
            raise ValueError(f"Jet powers must be non-negative integers, got {k!r}")
        if k == 0:
            return self * 0.0 + 1.0
        if k == 1:
            return self
        v = self.v
        return self.apply(v**k, k * v ** (k - 1), k * (k - 1) * v ** max(k - 2, 0))


def sin(u: Jet) -> Jet:
    s, c = np.sin(u.v), np.cos(u.v)
    return u.apply(s, c, -s)


def cos(u: Jet) -> Jet:
    s, c = np.sin(u.v), np.cos(u.v)
    return u.apply(c, -s, -c)


def sqrt(u: Jet) -> Jet:
    """sqrt(u) for u > 0; slopes 1/(2 sqrt u) and -1/(4 u sqrt u)."""
    r = np.sqrt(u.v)
    if u.g is None:  # value only: no slopes, which are infinite at u = 0
        return Jet(r)
    return u.apply(r, 0.5 / r, -0.25 / (u.v * r))


def atan2(a: Jet, b: Jet) -> Jet:
    """Angle of the point (b, a): f_a = b/r2, f_b = -a/r2, r2 = a^2 + b^2.

    f_aa = -2ab/r2^2 = -f_bb and f_ab = (a^2 - b^2)/r2^2. Written as a two-argument primitive
    so that no division by a (or b) appears: near the polar axis the angle stays accurate.
    """
    r2 = a.v**2 + b.v**2
    v = np.arctan2(a.v, b.v)
    g = h = None
    if a.g is not None:
        fa, fb = b.v / r2, -a.v / r2
        g = _col(fa, 2) * a.g + _col(fb, 2) * b.g
    if a.h is not None:
        faa = -2.0 * a.v * b.v / r2**2
        fab = (a.v**2 - b.v**2) / r2**2
        ab = _outer(a.g, b.g)
        h = (_col(faa, 3) * (_outer(a.g, a.g) - _outer(b.g, b.g))
             + _col(fab, 3) * (ab + np.swapaxes(ab, 1, 2))
             + _col(fa, 3) * a.h + _col(fb, 3) * b.h)
    return Jet(v, g, h)
