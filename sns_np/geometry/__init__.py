"""Differential geometry and the Laplace-Beltrami operator on any surface map.

Depends only on the surface-map and field protocols (:mod:`sns_np.protocol`), never on
:mod:`sns_np.nn`. Conventions (DESIGN.md): ``n`` outward, ``II_ab = -n . S_ab`` with the
sphere-curvature term, convex-positive curvature, ``H = (kmin + kmax) / 2``,
``Delta_S`` negative semi-definite. The equations are mapped to these functions in
``docs/geometry.md``.

Calling the map
    :func:`differential_quantities` (everything from one jet call), :func:`normals`,
    :func:`first_fundamental_form`, :func:`area_element`, :func:`second_fundamental_form`,
    :func:`mean_curvature`, :func:`gaussian_curvature`, :func:`principal_curvatures`,
    :func:`principal_directions`, :func:`surface_gradient`, :func:`surface_divergence`,
    :func:`laplace_beltrami`, and the frame :func:`tangent_frame`.

From jets already computed (``*_from_jets`` and friends)
    :func:`tangent_jacobian`, :func:`frame_jets`, :func:`sphere_second_derivatives`,
    :func:`normals_from_jets`, :func:`normals_from_tangents`,
    :func:`first_fundamental_form_from_jets`, :func:`area_element_from_jets`,
    :func:`inverse_metric`,
    :func:`second_fundamental_form_from_jets`, :func:`curvatures_from_forms`,
    :func:`principal_from_jets`, :func:`metric_conditioning`,
    :func:`surface_gradient_from_jets`, :func:`surface_divergence_from_jets`,
    :func:`surface_gradient_ambient`, :func:`surface_divergence_ambient`,
    :func:`sphere_field_chart_jets`, :func:`ambient_field_chart_jets`,
    :func:`sphere_field_extension`, :func:`laplace_beltrami_mean_curvature_from_jets`,
    :func:`laplace_beltrami_divgrad_from_jets`.

Examples
--------
>>> import numpy as np
>>> from sns_np.shapes import Ellipsoid
>>> q = differential_quantities(Ellipsoid(2.0, 1.0, 1.0), np.array([[1.0, 0.0, 0.0]]))
>>> float(q.K[0]), float(q.H[0])  # K = a^2 / (b^2 c^2), H = a / b^2 at the tip
(4.0, 2.0)
"""

from .calculus import (
    ambient_field_chart_jets,
    sphere_field_chart_jets,
    surface_divergence,
    surface_divergence_ambient,
    surface_divergence_from_jets,
    surface_gradient,
    surface_gradient_ambient,
    surface_gradient_from_jets,
)
from .forms import (
    area_element_from_jets,
    curvatures_from_forms,
    first_fundamental_form_from_jets,
    frame_jets,
    inverse_metric,
    metric_conditioning,
    normals_from_jets,
    normals_from_tangents,
    principal_from_jets,
    second_fundamental_form_from_jets,
    sphere_second_derivatives,
    tangent_jacobian,
)
from .frame import sphere_points, tangent_frame
from .laplace_beltrami import (
    laplace_beltrami,
    laplace_beltrami_divgrad_from_jets,
    laplace_beltrami_mean_curvature_from_jets,
    sphere_field_extension,
)
from .quantities import (
    DifferentialQuantities,
    area_element,
    differential_quantities,
    first_fundamental_form,
    gaussian_curvature,
    mean_curvature,
    normals,
    principal_curvatures,
    principal_directions,
    second_fundamental_form,
)

__all__ = [
    "tangent_frame", "sphere_points",
    "DifferentialQuantities", "differential_quantities", "normals", "first_fundamental_form",
    "area_element", "second_fundamental_form", "mean_curvature", "gaussian_curvature",
    "principal_curvatures", "principal_directions",
    "surface_gradient", "surface_divergence", "laplace_beltrami",
    "tangent_jacobian", "frame_jets", "sphere_second_derivatives", "normals_from_jets",
    "normals_from_tangents",
    "first_fundamental_form_from_jets", "area_element_from_jets", "inverse_metric",
    "second_fundamental_form_from_jets", "curvatures_from_forms", "principal_from_jets",
    "metric_conditioning", "surface_gradient_from_jets", "surface_divergence_from_jets",
    "surface_gradient_ambient", "surface_divergence_ambient", "sphere_field_chart_jets",
    "ambient_field_chart_jets", "sphere_field_extension",
    "laplace_beltrami_mean_curvature_from_jets", "laplace_beltrami_divgrad_from_jets",
]
