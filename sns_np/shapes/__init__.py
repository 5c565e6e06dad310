"""Analytic surfaces and scalar fields with exact ambient jets of order 0-2.

Surfaces (surface-map protocol, DESIGN.md):

* :class:`Sphere` ``(radius)`` and :class:`Ellipsoid` ``(a, b, c)``: linear maps ``r x`` and
  ``diag(a, b, c) x``; :class:`LinearShape` ``(A)`` for any matrix.
* :class:`PerturbedEllipsoid`: a smooth non-homogeneous map ``A x + eps B sin(W x + c)``.
* The paper's radial shapes :class:`Flower`, :class:`Bobble`, :class:`Spike`, :class:`Tree`
  (``scale``; ``.small()`` for the SMALL* scales) and :func:`radial_shape` by name.

Every surface has ``jet(x, order)``, ``__call__(x)`` and ``mesh(level)``.

Fields (field protocol): :class:`LinearField`, :func:`coordinate_field`,
:class:`SphericalHarmonic`, :class:`SineWaveField`, :class:`PullbackField`,
:class:`ComponentField`.

Examples
--------
>>> import numpy as np
>>> from sns_np.shapes import Ellipsoid
>>> y, J, D2 = Ellipsoid(2.0, 1.0, 1.0).jet(np.array([[1.0, 0.0, 0.0]]), 2)
>>> y
array([[2., 0., 0.]])
"""

from .fields import (
    ComponentField,
    LinearField,
    PullbackField,
    SineWaveField,
    SphericalHarmonic,
    coordinate_field,
)
from .radial import SMALL_SCALES, Bobble, Flower, RadialShape, Spike, Tree, radial_shape
from .surfaces import AnalyticShape, Ellipsoid, LinearShape, PerturbedEllipsoid, Sphere

__all__ = [
    "AnalyticShape", "LinearShape", "Sphere", "Ellipsoid", "PerturbedEllipsoid",
    "RadialShape", "Flower", "Bobble", "Spike", "Tree", "radial_shape", "SMALL_SCALES",
    "LinearField", "coordinate_field", "SphericalHarmonic", "SineWaveField", "PullbackField",
    "ComponentField",
]
