"""The SphericalNeuralSurface and its fitting.

SphericalNeuralSurface   network + output transform; a surface map; save/load; to_mesh
fit_mesh, fit_shape      fitting to a mesh or an analytic map (also as class methods)
FitReport                what a fit did and its held-out errors
FitOptions               the fitting options: defaults, help, checks, resume key

fit_sdf                  fitting to the zero set of a signed distance function (also a class
                         method; re-exported by :mod:`sns_np.flows`)
"""

from ..options import FitOptions
from .fit import DEFAULTS, FitReport, fit_mesh, fit_sampler, fit_shape
from .losses import (
    hessian_loss,
    jacobian_loss,
    normals_from_tangents,
    own_area_weights,
    position_normal_loss,
)
from .model import SphericalNeuralSurface
from .sdf import SDFFitReport, fit_sdf, project_to_zero_set

__all__ = ["SphericalNeuralSurface", "fit_mesh", "fit_shape", "fit_sampler", "FitReport",
           "FitOptions", "DEFAULTS", "position_normal_loss", "jacobian_loss", "hessian_loss",
           "normals_from_tangents", "own_area_weights", "fit_sdf", "SDFFitReport",
           "project_to_zero_set"]
