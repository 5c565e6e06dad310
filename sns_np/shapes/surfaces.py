"""Analytic surface maps with exact ambient jets: linear maps, spheres, ellipsoids, a wavy one.

Each class follows the surface-map protocol of DESIGN.md: ``jet(x, order)`` returns ``y``
(n, 3), ``J`` (n, 3, 3) with ``J[k, i, a] = dS_i/dx_a`` and ``D2`` (n, 3, 3, 3), all derivatives
taken in R^3. The maps are defined on all of R^3 (not only on the sphere), so their 3 x 3
Jacobians are invertible, like a network's, and central differences off the sphere are valid.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_points, check_order, check_positive_float, check_positive_int

__all__ = ["AnalyticShape", "LinearShape", "Sphere", "Ellipsoid", "PerturbedEllipsoid"]


class AnalyticShape:
    """Base class: a surface map ``S: R^3 -> R^3`` with exact jets and a mesher.

    Examples
    --------
    >>> class Cone(AnalyticShape):       # a custom map only needs jet(x, order)
    ...     def jet(self, x, order=0):
    ...         y = x * [1.0, 1.0, 2.0]
    ...         J = np.broadcast_to(np.diag([1.0, 1.0, 2.0]), (len(x), 3, 3))
    ...         return (y, J, np.zeros((len(x), 3, 3, 3)))[:order + 1] if order else y
    >>> V, F = Cone().mesh(1)
    >>> float(V[:, 2].max())
    2.0
    """

    def jet(self, x, order: int = 0):  # pragma: no cover - abstract
        """Value ``y`` (n, 3), and with ``order`` 1 or 2 also ``J`` (n, 3, 3) and ``D2``
        (n, 3, 3, 3), ambient (DESIGN.md).

        Examples
        --------
        >>> y, J, D2 = Ellipsoid(1.0, 2.0, 3.0).jet(np.array([[0.0, 0.0, 1.0]]), order=2)
        >>> y, J[0].diagonal(), float(abs(D2).max())
        (array([[0., 0., 3.]]), array([1., 2., 3.]), 0.0)
        """
        raise NotImplementedError

    def __call__(self, x) -> np.ndarray:
        """Positions ``S(x)``, (n, 3); the same as ``jet(x, 0)``."""
        return self.jet(x, 0)

    def mesh(self, level: int = 4):
        """The icosphere of ``level`` pushed through the map, vertices exactly on the surface.

        Parameters
        ----------
        level : int >= 0
            Subdivision level of :func:`sns_np.mesh.icosphere` (``10 * 4**level + 2`` vertices).

        Returns
        -------
        V : (m, 3) float array, ``S(icosphere vertices)``
        F : (k, 3) int array, counter-clockwise seen from outside for an
            orientation-preserving map

        Examples
        --------
        >>> V, F = Ellipsoid(2.0, 1.0, 1.0).mesh(1)
        >>> V.shape, F.shape
        ((42, 3), (80, 3))
        """
        from ..mesh.icosphere import icosphere

        P, F = icosphere(check_positive_int(level, "level", minimum=0))
        return self.jet(P, 0), F


class LinearShape(AnalyticShape):
    """The linear map ``S(x) = A x``: ``J = A``, ``D2 = 0``.

    All of the curvature of a linear image of the sphere comes from the sphere-curvature term
    of the second fundamental form, ``S_ab = D2[e_a, e_b] - (e_a . e_b) J p = -(e_a . e_b) A p``.

    Parameters
    ----------
    A : (3, 3) float array, invertible with ``det A > 0`` for an outward-oriented surface

    Examples
    --------
    >>> S = LinearShape(np.diag([1.0, 2.0, 3.0]))
    >>> y, J = S.jet(np.array([[0.0, 0.0, 1.0]]), 1)
    >>> y
    array([[0., 0., 3.]])
    """

    def __init__(self, A):
        A = np.asarray(A, dtype=np.float64)
        if A.shape != (3, 3) or not np.all(np.isfinite(A)):
            raise ValueError(f"A must be a finite (3, 3) matrix, got shape {A.shape}")
        self.A = A

    def jet(self, x, order: int = 0):
        """``y = A x``, ``J = A``, ``D2 = 0`` at the points ``x`` (n, 3).

        Examples
        --------
        >>> S = LinearShape([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]])
        >>> y, J = S.jet(np.array([[0.0, 1.0, 0.0]]), order=1)
        >>> y, bool(np.array_equal(J[0], S.A))
        (array([[0.5, 1. , 0. ]]), True)
        """
        x = as_points(x, "x")
        order = check_order(order)
        y = x @ self.A.T
        if order == 0:
            return y
        n = x.shape[0]
        J = np.broadcast_to(self.A, (n, 3, 3)).copy()
        if order == 1:
            return y, J
        return y, J, np.zeros((n, 3, 3, 3))

    def __repr__(self):
        return f"{type(self).__name__}(A={self.A.tolist()})"


class Sphere(LinearShape):
    """Sphere of radius ``r`` as the linear map ``x -> r x`` (H = 1/r, K = 1/r^2).

    Examples
    --------
    >>> Sphere(2.0)(np.array([[1.0, 0.0, 0.0]]))
    array([[2., 0., 0.]])
    """

    def __init__(self, radius: float = 1.0):
        self.radius = check_positive_float(radius, "radius")
        super().__init__(self.radius * np.eye(3))

    def __repr__(self):
        return f"Sphere(radius={self.radius!r})"


class Ellipsoid(LinearShape):
    """Ellipsoid ``x^2/a^2 + y^2/b^2 + z^2/c^2 = 1`` as the linear map ``diag(a, b, c)``.

    Examples
    --------
    >>> Ellipsoid(3.0, 2.0, 1.0)(np.array([[0.0, 1.0, 0.0]]))
    array([[0., 2., 0.]])
    """

    def __init__(self, a: float = 1.0, b: float = 1.0, c: float = 1.0):
        self.axes = tuple(check_positive_float(v, name) for v, name in
                          ((a, "a"), (b, "b"), (c, "c")))
        super().__init__(np.diag(self.axes))

    def __repr__(self):
        return "Ellipsoid(a={!r}, b={!r}, c={!r})".format(*self.axes)


def _rotation(axis, angle):
    """Rodrigues' rotation about ``axis`` by ``angle``."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


class PerturbedEllipsoid(AnalyticShape):
    """A smooth non-homogeneous map: ``S(x) = A x + eps B sin(W x + c)``.

    ``A = diag(a, b, c)``, ``W = frequency * Q1`` and ``B = Q2`` with fixed rotations ``Q1``,
    ``Q2`` and a fixed phase vector ``c``; ``sin`` acts entrywise. Its derivatives

        J = A + eps B diag(cos u) W,     D2_iab = -eps sum_k B_ik sin(u_k) W_ka W_kb,

    with ``u = W x + c``, do not vanish in the radial direction, so geometry code must use the
    sphere-curvature term and off-sphere second derivatives correctly. Because
    ``||eps B diag(cos u) W|| <= eps * frequency < min(a, b, c)``, the map is a diffeomorphism of
    R^3 (injective, invertible Jacobian everywhere) and the surface is embedded and regular.

    Parameters
    ----------
    a, b, c : float > 0, semi-axes of the underlying ellipsoid
    amplitude : float >= 0, ``eps``
    frequency : float > 0; ``amplitude * frequency`` must be below ``min(a, b, c)``

    Examples
    --------
    >>> S = PerturbedEllipsoid()
    >>> S.jet(np.array([[0.0, 0.0, 1.0]]), 2)[2].shape
    (1, 3, 3, 3)
    """

    def __init__(self, a: float = 1.2, b: float = 1.0, c: float = 0.8,
                 amplitude: float = 0.1, frequency: float = 2.5):
        axes = tuple(check_positive_float(v, name) for v, name in ((a, "a"), (b, "b"), (c, "c")))
        eps = check_positive_float(amplitude, "amplitude", allow_zero=True)
        freq = check_positive_float(frequency, "frequency")
        if eps * freq >= min(axes):
            raise ValueError(
                f"amplitude * frequency = {eps * freq:g} must be below min(a, b, c) = "
                f"{min(axes):g}, otherwise the map may fold over")
        self.axes, self.amplitude, self.frequency = axes, eps, freq
        self.A = np.diag(axes)
        self.W = freq * _rotation([1.0, 2.0, 3.0], 0.7)
        self.B = _rotation([-2.0, 1.0, 0.5], 1.1)
        self.c = np.array([0.3, -1.2, 2.0])

    def jet(self, x, order: int = 0):
        """``y = A x + eps B sin(W x + c)`` with its exact ``J`` and ``D2``.

        Examples
        --------
        >>> from sns_np.testing import check_jet
        >>> p = np.array([[0.6, 0.0, 0.8], [0.0, -1.0, 0.0]])
        >>> S = PerturbedEllipsoid()
        >>> err = check_jet(S, p, order=2)
        >>> bool(max(err.values()) < 1e-6)          # exact derivatives vs central differences
        True
        """
        x = as_points(x, "x")
        order = check_order(order)
        u = x @ self.W.T + self.c
        eps, B, W = self.amplitude, self.B, self.W
        y = x @ self.A.T + eps * np.sin(u) @ B.T
        if order == 0:
            return y
        J = self.A + eps * np.einsum("ik,nk,ka->nia", B, np.cos(u), W)
        if order == 1:
            return y, J
        D2 = -eps * np.einsum("ik,nk,ka,kb->niab", B, np.sin(u), W, W, optimize=True)
        return y, J, D2

    def __repr__(self):
        return ("PerturbedEllipsoid(a={!r}, b={!r}, c={!r}, ".format(*self.axes)
                + f"amplitude={self.amplitude!r}, frequency={self.frequency!r})")
