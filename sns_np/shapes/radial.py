"""The paper's radial test shapes: FLOWER, BOBBLE, SPIKE, TREE and their SMALL* scales.

Each surface is ``{s (1 + g(theta, phi)) p : p on the unit sphere}`` with the polar angle
``theta = arccos(z/|x|)`` and the azimuth ``phi = atan2(y, x)``; with
``Q = (theta (pi - theta))^2``:

======  ====================================================================  ==========
family  g(theta, phi)                                                          SMALL s
======  ====================================================================  ==========
FLOWER  0.3 (0.4 Q cos^2(18 theta) + 0.6 Q sin^2(6 phi + 18 theta))            0.366
BOBBLE  0.1 (0.4 Q cos^2(12 theta) + 0.4 Q sin^2(12 phi + 6 theta))            0.679
SPIKE   0.4 sin^2(theta) sin(6 theta) sin(6 phi)                               0.772
TREE    0.05 (2 theta^3 sin^2(6 theta) + 0.6 Q sin^2(6 phi + 6 theta^2))      0.301
======  ====================================================================  ==========

The ambient map is made 1-homogeneous, ``S(x) = s (1 + G(x)) x`` with ``G(x) = g(x/|x|)``,
so that the radial derivative is ``J p = S(p)`` and the 3 x 3 Jacobian is invertible
(``det J = s^3 (1 + G)^3 |x|^0`` on the sphere); on the sphere it is the same surface.

Jets and the poles
------------------
``G`` is evaluated with a private Taylor arithmetic (value, gradient, Hessian) from
``rho = sqrt(x^2 + y^2)``, ``theta = atan2(rho, z)``, ``pi - theta = atan2(rho, -z)`` and
``phi = atan2(y, x)`` (:class:`PolarAngles`). The two-argument ``atan2`` rule never divides by
``z`` or forms ``1 - cos^2``, and the factors that vanish at a pole (``Q``, ``sin(k theta)``)
are computed from the angle to the nearest pole, so the jets stay accurate to round-off
arbitrarily close to both poles (tested at ``rho = 1e-7`` against 40-digit symbolic
derivatives), although ``theta`` and ``phi`` themselves have singular derivatives there.

Regularity exactly at the poles (``x = y = 0``), where ``g`` vanishes together with its
gradient in every family:

* FLOWER, BOBBLE, TREE contain ``Q sin^2(k phi + ...)``, i.e. a term
  ``~ theta^2 cos(2 k phi)``: the shape is C^1 (in fact C^{1,1}, curvature bounded) but **not
  twice differentiable** at either pole; the curvature has a direction-dependent limit.
* SPIKE is ``~ theta^3 sin(6 phi)`` near the poles: C^2 but not C^3; its Hessian at the poles
  is exactly 0.

At an exact pole point the order-2 jet returns, by convention, the Hessian of the
phi-average of ``G``, ``2 c / |x|^2 diag(1, 1, 0)`` where ``g ~ c t^2`` on average (``t`` the
angle to the pole); the coefficients ``c`` are derived beside each family and checked in the
tests. Gauss-Bonnet still holds (the surfaces are C^{1,1}); quadratures should avoid the poles
(:func:`sns_np.quadrature.sphere_quadrature` does).
"""

from __future__ import annotations

import numpy as np

from .._validation import as_points, check_order, check_positive_float
from ._jet import Jet, atan2, cos, sin, sqrt
from .surfaces import AnalyticShape

__all__ = ["RadialShape", "PolarAngles", "Flower", "Bobble", "Spike", "Tree", "radial_shape",
           "SMALL_SCALES"]

PI = np.pi

#: the SMALL* scales of the paper's shape set
SMALL_SCALES = {"flower": 0.366, "bobble": 0.679, "spike": 0.772, "tree": 0.301}

#: points with rho <= _POLE_RTOL |x| are treated as exact poles (keeps 1/rho^2 finite)
_POLE_RTOL = 1e-60


class PolarAngles:
    """``theta``, ``pi - theta`` and ``phi`` as jets, with trigonometry that stays accurate at
    both poles.

    ``theta = atan2(rho, z)`` is accurate near the north pole but ``pi - theta`` computed from
    it loses all relative accuracy near the south pole (and ``sin(6 theta)`` with it); so
    ``theta_c = pi - theta`` is evaluated separately as ``atan2(rho, -z)`` and the factors that
    vanish at a pole are written through the angle to the nearest pole ``t``:
    ``sin(k theta) = s_k sin(k t)``, ``cos(k theta) = c_k cos(k t)`` with ``s_k = c_k = 1`` in
    the north and ``s_k = (-1)^(k+1)``, ``c_k = (-1)^k`` in the south.
    """

    def __init__(self, X, Y, Z):
        rho = sqrt(X * X + Y * Y)
        self.theta, self.theta_c, self.phi = atan2(rho, Z), atan2(rho, -Z), atan2(Y, X)
        self.south = Z.v < 0
        t = self.theta
        self._t = Jet(np.where(self.south, self.theta_c.v, t.v),
                      None if t.g is None else np.where(self.south[:, None], -t.g, t.g),
                      None if t.h is None else np.where(self.south[:, None, None], -t.h, t.h))

    def sin(self, k: int) -> Jet:
        """``sin(k theta)`` for an integer ``k``."""
        return sin(k * self._t) * np.where(self.south, (-1.0) ** (k + 1), 1.0)

    def cos(self, k: int) -> Jet:
        """``cos(k theta)`` for an integer ``k``."""
        return cos(k * self._t) * np.where(self.south, (-1.0) ** k, 1.0)

    def Q(self) -> Jet:
        """``Q = (theta (pi - theta))^2``, accurate relative to its size at both poles."""
        return (self.theta * self.theta_c) ** 2


class RadialShape(AnalyticShape):
    """A radial graph ``S(x) = s (1 + G(x)) x`` over the unit sphere, ``G(x) = g(x / |x|)``.

    Subclasses define ``g(a)`` on :class:`PolarAngles` ``a`` and the pole coefficients
    ``pole_c = (c_north, c_south)`` of the phi-averaged ``g ~ c t^2`` (see the module notes).

    Parameters
    ----------
    scale : float > 0, ``s``

    Notes
    -----
    With ``G_a``, ``G_ab`` the ambient derivatives of ``G``:
    ``J_ia = s ((1 + G) delta_ia + x_i G_a)`` and
    ``D2_iab = s (x_i G_ab + delta_ia G_b + delta_ib G_a)``.

    Examples
    --------
    >>> S = Spike()                     # a RadialShape: S(x) = s (1 + G(x)) x
    >>> p = np.array([[0.6, 0.0, 0.8]])
    >>> y = S(p)
    >>> bool(np.allclose(y / np.linalg.norm(y), p))   # radial: y is a multiple of p
    True
    """

    family = ""
    pole_c = (0.0, 0.0)

    def __init__(self, scale: float = 1.0):
        self.scale = check_positive_float(scale, "scale")

    @classmethod
    def small(cls):
        """The paper's SMALL* version of this family.

        Examples
        --------
        >>> Flower.small(), Tree.small().scale
        (Flower(scale=0.366), 0.301)
        """
        return cls(SMALL_SCALES[cls.family])

    def g(self, a: PolarAngles) -> Jet:  # pragma: no cover - abstract
        """The radius perturbation ``g(theta, phi)`` as a :class:`Jet` of the ambient point
        (each family defines it).

        Examples
        --------
        >>> from sns_np.shapes.radial import PolarAngles
        >>> from sns_np.shapes._jet import Jet
        >>> x = np.array([[0.6, 0.0, 0.8]])
        >>> G = Spike().g(PolarAngles(*Jet.coordinates(x, 0)))
        >>> bool(np.allclose(G.v, Spike().radius_function(x).v))
        True
        """
        raise NotImplementedError

    def radius_function(self, x, order: int = 0):
        """``G(x) = g(theta(x), phi(x))`` as a :class:`Jet` (value, gradient, Hessian in R^3).

        Examples
        --------
        >>> G = Bobble().radius_function(np.array([[0.6, 0.0, 0.8]]), order=2)
        >>> G.v.shape, G.g.shape, G.h.shape                 # value, gradient, Hessian of G
        ((1,), (1, 3), (1, 3, 3))
        """
        x = as_points(x, "x")
        order = check_order(order)
        r2 = np.einsum("ka,ka->k", x, x)
        if np.any(r2 == 0):
            k = int(np.argmax(r2 == 0))
            raise ValueError(f"radial shapes are undefined at the origin (point {k})")
        pole = x[:, 0] ** 2 + x[:, 1] ** 2 <= (_POLE_RTOL**2) * r2
        xs = x.copy()
        xs[pole] = [1.0, 0.0, 0.0]  # any regular point; the pole rows are overwritten below
        G = self.g(PolarAngles(*Jet.coordinates(xs, order)))
        if np.any(pole):
            # theta = 0 or pi, phi = 0: value-only evaluation is regular there
            G.v[pole] = self.g(PolarAngles(*Jet.coordinates(x[pole], 0))).v
            if order >= 1:
                G.g[pole] = 0.0
            if order >= 2:
                c = np.where(x[pole, 2] > 0, self.pole_c[0], self.pole_c[1]) / r2[pole]
                G.h[pole] = 0.0
                G.h[pole, 0, 0] = G.h[pole, 1, 1] = 2.0 * c
        return G

    def jet(self, x, order: int = 0):
        """Value, Jacobian and second derivatives of ``S(x) = s (1 + G(x)) x`` (ambient).

        Examples
        --------
        >>> from sns_np.testing import check_jet
        >>> p = np.array([[0.6, 0.0, 0.8], [0.0, -1.0, 0.0]])
        >>> err = check_jet(Flower(), p, order=2)
        >>> bool(max(err.values()) < 1e-5)          # exact derivatives vs central differences
        True
        """
        x = as_points(x, "x")
        order = check_order(order)
        G = self.radius_function(x, order)
        s = self.scale
        y = s * (1.0 + G.v)[:, None] * x
        if order == 0:
            return y
        eye = np.eye(3)
        J = s * ((1.0 + G.v)[:, None, None] * eye + x[:, :, None] * G.g[:, None, :])
        if order == 1:
            return y, J
        D2 = s * (x[:, :, None, None] * G.h[:, None, :, :]
                  + eye[None, :, :, None] * G.g[:, None, None, :]
                  + eye[None, :, None, :] * G.g[:, None, :, None])
        return y, J, D2

    def __repr__(self):
        return f"{type(self).__name__}(scale={self.scale!r})"


class Flower(RadialShape):
    """FLOWER: ``g = 0.3 (0.4 Q cos^2(18 theta) + 0.6 Q sin^2(6 phi + 18 theta))``.

    Not twice differentiable at the poles. Near either pole ``Q ~ pi^2 t^2``,
    ``cos^2(18 theta) -> 1`` and ``sin^2(...)`` averages 1/2, so ``c = 0.3 pi^2 (0.4 + 0.3)``.

    Examples
    --------
    >>> S = Flower()
    >>> S(np.array([[0.0, 0.0, 1.0]]))  # g = 0 at the poles
    array([[0., 0., 1.]])
    """

    family = "flower"
    pole_c = (0.21 * PI**2, 0.21 * PI**2)

    def g(self, a):
        """FLOWER's ``g(theta, phi)`` (see the class docstring).

        Examples
        --------
        >>> from sns_np.shapes.radial import PolarAngles
        >>> from sns_np.shapes._jet import Jet
        >>> equator = np.array([[1.0, 0.0, 0.0]])           # theta = pi/2, phi = 0
        >>> theta = np.pi / 2
        >>> Q = (theta * (np.pi - theta)) ** 2
        >>> g = Flower().g(PolarAngles(*Jet.coordinates(equator, 0))).v
        >>> bool(np.allclose(g, 0.3 * (0.4 * Q * np.cos(18 * theta) ** 2
        ...                            + 0.6 * Q * np.sin(18 * theta) ** 2)))
        True
        """
        Q, t, f = a.Q(), a.theta, a.phi
        return 0.3 * (0.4 * Q * a.cos(18) ** 2 + 0.6 * Q * sin(6 * f + 18 * t) ** 2)


class Bobble(RadialShape):
    """BOBBLE: ``g = 0.1 (0.4 Q cos^2(12 theta) + 0.4 Q sin^2(12 phi + 6 theta))``.

    Not twice differentiable at the poles; ``c = 0.1 pi^2 (0.4 + 0.2)`` at both.

    Examples
    --------
    >>> S = Bobble.small()
    >>> float(np.linalg.norm(S(np.array([[0.0, 0.0, 1.0]]))))    # g = 0 at the poles: radius s
    0.679
    """

    family = "bobble"
    pole_c = (0.06 * PI**2, 0.06 * PI**2)

    def g(self, a):
        """BOBBLE's ``g(theta, phi)`` (see the class docstring).

        Examples
        --------
        >>> from sns_np.shapes.radial import PolarAngles
        >>> from sns_np.shapes._jet import Jet
        >>> x = np.array([[0.0, 0.6, 0.8]])
        >>> G = Bobble().g(PolarAngles(*Jet.coordinates(x, 0)))
        >>> bool(np.allclose(G.v, Bobble().radius_function(x).v)), bool(G.v[0] >= 0)
        (True, True)
        """
        Q, t, f = a.Q(), a.theta, a.phi
        return 0.1 * (0.4 * Q * a.cos(12) ** 2 + 0.4 * Q * sin(12 * f + 6 * t) ** 2)


class Spike(RadialShape):
    """SPIKE: ``g = 0.4 sin^2(theta) sin(6 theta) sin(6 phi)``.

    ``g ~ 2.4 t^3 sin(6 phi)`` near the poles: C^2 there (Hessian 0, ``c = 0``), not C^3.

    Examples
    --------
    >>> S = Spike()
    >>> p = np.array([[np.cos(0.3), np.sin(0.3), 0.0]])    # on the equator sin(6 theta) = 0
    >>> round(float(np.linalg.norm(S(p))), 9)              # so g = 0 there: radius s = 1
    1.0
    """

    family = "spike"
    pole_c = (0.0, 0.0)

    def g(self, a):
        """SPIKE's ``g(theta, phi)`` (see the class docstring).

        Examples
        --------
        >>> from sns_np.shapes.radial import PolarAngles
        >>> from sns_np.shapes._jet import Jet
        >>> t, f = 1.0, 0.2                                  # theta, phi
        >>> x = np.array([[np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)]])
        >>> G = Spike().g(PolarAngles(*Jet.coordinates(x, 0)))
        >>> bool(np.allclose(G.v, 0.4 * np.sin(t) ** 2 * np.sin(6 * t) * np.sin(6 * f)))
        True
        """
        return 0.4 * a.sin(1) ** 2 * a.sin(6) * sin(6 * a.phi)


class Tree(RadialShape):
    """TREE: ``g = 0.05 (2 theta^3 sin^2(6 theta) + 0.6 Q sin^2(6 phi + 6 theta^2))``.

    Not twice differentiable at the poles. North: ``theta^3 sin^2(6 theta) = O(t^5)``, so
    ``c = 0.05 * 0.3 pi^2``; south: ``theta^3 sin^2(6 theta) ~ 36 pi^3 t^2``, so
    ``c = 0.05 (72 pi^3 + 0.3 pi^2)``.

    Examples
    --------
    >>> S = Tree.small()
    >>> V, F = S.mesh(2)
    >>> V.shape, bool(np.linalg.norm(V, axis=1).min() >= S.scale)   # g >= 0: outside radius s
    ((162, 3), True)
    """

    family = "tree"
    pole_c = (0.015 * PI**2, 0.05 * (72 * PI**3 + 0.3 * PI**2))

    def g(self, a):
        """TREE's ``g(theta, phi)`` (see the class docstring).

        Examples
        --------
        >>> from sns_np.shapes.radial import PolarAngles
        >>> from sns_np.shapes._jet import Jet
        >>> x = np.array([[0.0, 0.0, -1.0]])                 # the south pole: theta = pi, Q = 0
        >>> t = np.pi
        >>> G = Tree().g(PolarAngles(*Jet.coordinates(x, 0)))
        >>> bool(np.allclose(G.v, 0.05 * 2 * t ** 3 * np.sin(6 * t) ** 2))
        True
        """
        t, f = a.theta, a.phi
        return 0.05 * (2 * t**3 * a.sin(6) ** 2 + 0.6 * a.Q() * sin(6 * f + 6 * t**2) ** 2)


_FAMILIES = {"flower": Flower, "bobble": Bobble, "spike": Spike, "tree": Tree}


def radial_shape(name: str) -> RadialShape:
    """A radial test shape by its paper name: FLOWER, SMALLFLOWER, BOBBLE, ..., SMALLTREE.

    Examples
    --------
    >>> radial_shape("SMALLSPIKE")
    Spike(scale=0.772)
    """
    key = str(name).lower()
    small = key.startswith("small")
    fam = key[5:] if small else key
    if fam not in _FAMILIES:
        names = sorted(f.upper() for f in _FAMILIES)
        raise ValueError(f"unknown radial shape {name!r}; expected one of {names} or "
                         f"{['SMALL' + n for n in names]}")
    cls = _FAMILIES[fam]
    return cls.small() if small else cls()

