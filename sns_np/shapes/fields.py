"""Analytic scalar fields with exact ambient jets, for tests and demos.

Every class follows the field protocol of DESIGN.md: ``jet(x, order)`` returns the value (n,),
the gradient (n, 3) and the Hessian (n, 3, 3), all with respect to ``x`` in R^3. A field can be
used on the parameter sphere (``domain="sphere"`` in :mod:`sns_np.geometry`: evaluated at
``p``) or around the surface in R^3 (``domain="ambient"``: evaluated at ``S(p)``).

* :class:`LinearField`, :func:`coordinate_field` -- ``a . x + b``
* :class:`SphericalHarmonic` -- real spherical harmonics, extended as solid harmonics
* :class:`SineWaveField` -- a variable-frequency sine wave
* :class:`PullbackField` -- ``f o S``, an ambient field pulled back to the sphere
* :class:`ComponentField` -- one coordinate ``S(p)_i`` of a surface map, a sphere field
"""

from __future__ import annotations

from math import factorial, pi, sqrt

import numpy as np

from .._validation import as_points, check_order, check_positive_int
from ..protocol import field_jet, surface_jet
from ._jet import Jet, sin

__all__ = ["LinearField", "coordinate_field", "SphericalHarmonic", "SineWaveField",
           "PullbackField", "ComponentField"]


def _out(J: Jet, order):
    if order == 0:
        return J.v
    return (J.v, J.g) if order == 1 else (J.v, J.g, J.h)


class LinearField:
    """``f(x) = a . x + b``: gradient ``a``, Hessian 0.

    Examples
    --------
    >>> LinearField([1.0, 2.0, 0.0]).jet(np.array([[1.0, 1.0, 1.0]]), 0)
    array([3.])
    """

    def __init__(self, a, b: float = 0.0):
        a = np.asarray(a, dtype=np.float64)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ValueError(f"a must be a finite vector of shape (3,), got {a.shape}")
        self.a, self.b = a, float(b)

    def jet(self, x, order: int = 0):
        """Value ``a . x + b`` (n,), gradient ``a`` (n, 3) and Hessian 0 (n, 3, 3).

        Examples
        --------
        >>> f = LinearField([1.0, 2.0, 0.0], b=0.5)
        >>> v, g, H = f.jet(np.array([[1.0, 0.0, 0.0]]), order=2)
        >>> v, g, float(abs(H).max())
        (array([1.5]), array([[1., 2., 0.]]), 0.0)
        """
        x = as_points(x, "x")
        order = check_order(order)
        v = x @ self.a + self.b
        if order == 0:
            return v
        g = np.broadcast_to(self.a, x.shape).copy()
        return (v, g) if order == 1 else (v, g, np.zeros((x.shape[0], 3, 3)))


def coordinate_field(i: int) -> LinearField:
    """The coordinate function ``x_i`` (i = 0, 1, 2) as a :class:`LinearField`.

    Examples
    --------
    >>> coordinate_field(2).jet(np.array([[0.0, 0.6, 0.8]]), 0)
    array([0.8])
    """
    if i not in (0, 1, 2):
        raise ValueError(f"coordinate index must be 0, 1 or 2, got {i!r}")
    return LinearField(np.eye(3)[i])


class SphericalHarmonic:
    """Real spherical harmonic ``Y_lm``, orthonormal on the unit sphere, no Condon-Shortley phase.

    ``Y_l0 = N_l0 P_l(cos theta)``, ``Y_lm = sqrt(2) N_lm P_l^m(cos theta) cos(m phi)`` and
    ``Y_l,-m = sqrt(2) N_lm P_l^m(cos theta) sin(m phi)`` (m > 0), with
    ``N_lm = sqrt((2l+1)/(4 pi) (l-m)!/(l+m)!)``.

    Ambient extension: the **solid harmonic** ``r^l Y_lm(x/r)``, a homogeneous harmonic
    polynomial of degree ``l`` (Euclidean Laplacian 0, so ``Delta_S Y = -l(l+1) Y`` on the unit
    sphere comes entirely from the mean-curvature terms). It is built as
    ``N Pi_l^m(z, r^2) Re/Im (x + i y)^m`` with
    ``(l-m) Pi_l^m = (2l-1) z Pi_{l-1}^m - (l+m-1) r^2 Pi_{l-2}^m``,
    ``Pi_m^m = (2m-1)!!``, ``Pi_{m+1}^m = (2m+1) z Pi_m^m``.

    Parameters
    ----------
    l : int >= 0
    m : int, ``-l <= m <= l``

    Examples
    --------
    >>> Y = SphericalHarmonic(1, 0)  # sqrt(3/(4 pi)) z
    >>> float(Y.jet(np.array([[0.0, 0.0, 1.0]]), 0)[0]) == float(np.sqrt(3 / (4 * np.pi)))
    True
    """

    def __init__(self, l: int, m: int = 0):
        l = check_positive_int(l, "l", minimum=0)
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or abs(m) > l:
            raise ValueError(f"m must be an integer with |m| <= l = {l}, got {m!r}")
        self.l, self.m = l, int(m)
        am = abs(self.m)
        norm = sqrt((2 * l + 1) / (4 * pi) * factorial(l - am) / factorial(l + am))
        self._norm = norm * (sqrt(2.0) if am else 1.0)

    def jet(self, x, order: int = 0):
        """The solid harmonic ``r^l Y_lm(x / r)``: value (n,), gradient (n, 3), Hessian (n, 3, 3).

        Examples
        --------
        >>> from sns_np.testing import check_jet
        >>> p = np.array([[0.6, 0.0, 0.8], [0.0, -1.0, 0.0]])
        >>> Y = SphericalHarmonic(3, -2)
        >>> err = check_jet(Y, p, order=2)
        >>> bool(max(err.values()) < 1e-6)
        True
        >>> v, g, H = Y.jet(p, 2)
        >>> bool(np.allclose(np.trace(H, axis1=1, axis2=2), 0.0))  # a solid harmonic: Laplacian 0
        True
        """
        x = as_points(x, "x")
        order = check_order(order)
        X, Y, Z = Jet.coordinates(x, order)
        l, am = self.l, abs(self.m)
        # Re/Im (x + i y)^|m|
        C, S = X * 0.0 + 1.0, X * 0.0
        for _ in range(am):
            C, S = C * X - S * Y, C * Y + S * X
        r2 = X * X + Y * Y + Z * Z
        dfact = float(np.prod(np.arange(2 * am - 1, 0, -2))) if am else 1.0
        prev, cur = None, X * 0.0 + dfact
        for k in range(am + 1, l + 1):
            nxt = (2 * k - 1) * Z * cur
            if prev is not None:
                nxt = nxt - (k + am - 1) * r2 * prev
            prev, cur = cur, nxt / (k - am)
        ang = S if self.m < 0 else C
        return _out(self._norm * cur * ang, order)

    def __repr__(self):
        return f"SphericalHarmonic(l={self.l}, m={self.m})"


class SineWaveField:
    """A variable-frequency sine wave ``f(x) = sin(omega d . x + kappa (c . x)^2 + phase)``.

    The local frequency ``omega d + 2 kappa (c . x) c`` varies across the shape, as in the
    paper's test field. ``grad f = cos(u) grad u``,
    ``Hess f = -sin(u) grad u grad u^T + 2 kappa cos(u) c c^T``.

    Parameters
    ----------
    frequency : float, ``omega``
    chirp : float, ``kappa``
    direction, chirp_direction : (3,) float arrays (normalised internally)
    phase : float

    Examples
    --------
    >>> f = SineWaveField(frequency=2.0, chirp=0.0, direction=[1, 0, 0])
    >>> np.allclose(f.jet(np.array([[0.25, 0.0, 0.0]]), 0), np.sin(0.5 + 0.3))
    True
    """

    def __init__(self, frequency: float = 3.0, chirp: float = 1.5,
                 direction=(1.0, 2.0, 2.0), chirp_direction=(0.0, 0.6, -0.8),
                 phase: float = 0.3):
        def unit(v, name):
            v = np.asarray(v, dtype=np.float64)
            if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
                raise ValueError(f"{name} must be a finite non-zero (3,) vector, got {v}")
            return v / np.linalg.norm(v)

        self.frequency, self.chirp, self.phase = float(frequency), float(chirp), float(phase)
        self.direction = unit(direction, "direction")
        self.chirp_direction = unit(chirp_direction, "chirp_direction")

    def jet(self, x, order: int = 0):
        """Value (n,), gradient (n, 3) and Hessian (n, 3, 3) of the sine wave at ``x``.

        Examples
        --------
        >>> from sns_np.testing import check_jet
        >>> p = np.array([[0.6, 0.0, 0.8], [0.0, -1.0, 0.0]])
        >>> err = check_jet(SineWaveField(), p, order=2)
        >>> bool(max(err.values()) < 1e-6)
        True
        """
        x = as_points(x, "x")
        order = check_order(order)
        X = Jet.coordinates(x, order)
        d, c = self.direction, self.chirp_direction
        lin = X[0] * d[0] + X[1] * d[1] + X[2] * d[2]
        quad = X[0] * c[0] + X[1] * c[1] + X[2] * c[2]
        return _out(sin(self.frequency * lin + self.chirp * quad * quad + self.phase), order)


class PullbackField:
    """``g(p) = f(S(p))``: an ambient field pulled back through a surface map.

    ``grad g = J^T grad f`` and ``Hess g = J^T (Hess f) J + sum_i (grad f)_i D2_i``; the
    result is a field on the parameter sphere (``domain="sphere"``) whose surface values equal
    those of ``f`` used with ``domain="ambient"``.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> g = PullbackField(coordinate_field(2), Sphere(2.0))
    >>> g.jet(np.array([[0.0, 0.0, 1.0]]), 0)
    array([2.])
    """

    def __init__(self, field, surface):
        self.field, self.surface = field, surface

    def jet(self, x, order: int = 0):
        """Value, gradient ``J^T grad f`` and Hessian of ``f(S(p))`` (field protocol).

        Examples
        --------
        >>> from sns_np.shapes import Ellipsoid
        >>> S = Ellipsoid(1.0, 2.0, 3.0)
        >>> g = PullbackField(coordinate_field(1), S)       # g(p) = y-coordinate of S(p) = 2 p_y
        >>> v, grad = g.jet(np.array([[0.0, 1.0, 0.0]]), order=1)
        >>> v, grad
        (array([2.]), array([[0., 2., 0.]]))
        """
        x = as_points(x, "x")
        order = check_order(order)
        if order == 0:
            return field_jet(self.field, surface_jet(self.surface, x, 0), 0)
        out = surface_jet(self.surface, x, order)
        y, J = out[0], out[1]
        f = field_jet(self.field, y, order)
        grad = np.einsum("kia,ki->ka", J, f[1])
        if order == 1:
            return f[0], grad
        hess = (np.einsum("kia,kij,kjb->kab", J, f[2], J, optimize=True)
                + np.einsum("ki,kiab->kab", f[1], out[2]))
        return f[0], grad, hess


class ComponentField:
    """The coordinate ``S(p)_i`` of a surface map as a field: value ``y_i``, gradient ``J_i``,
    Hessian ``D2_i``. ``Delta_S`` of it is ``-2 H n_i``.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> ComponentField(Ellipsoid(1.0, 2.0, 3.0), 1).jet(np.array([[0.0, 1.0, 0.0]]), 0)
    array([2.])
    """

    def __init__(self, surface, i: int):
        if i not in (0, 1, 2):
            raise ValueError(f"component index must be 0, 1 or 2, got {i!r}")
        self.surface, self.i = surface, int(i)

    def jet(self, x, order: int = 0):
        """Value ``y_i`` (n,), gradient ``J_i`` (n, 3) and Hessian ``D2_i`` (n, 3, 3).

        Examples
        --------
        >>> from sns_np.shapes import Sphere
        >>> v, grad, H = ComponentField(Sphere(2.0), 0).jet(np.array([[1.0, 0.0, 0.0]]), 2)
        >>> v, grad
        (array([2.]), array([[2., 0., 0.]]))
        """
        x = as_points(x, "x")
        order = check_order(order)
        out = surface_jet(self.surface, x, order)
        if order == 0:
            return out[:, self.i]
        return tuple(a[:, self.i] for a in out)
