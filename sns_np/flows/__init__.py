"""Heat flow, mean curvature flow and fitting to a signed distance function (paper Sec. 6).

heat_flow               ``f_t = Delta_S f``: an explicit network scheme (``scheme="heun"``,
                        second order, or the paper's ``"euler"``) or an exact spectral one;
                        a :class:`HeatFlowResult`
mean_curvature_flow     ``X_t = Delta_S X = -2 H n`` by explicit steps (``scheme="heun"`` by
                        default, ``"midpoint"``, or the paper's ``"euler"``) and refits of the
                        surface network; a :class:`MeanCurvatureFlowResult`
stability_limit         ``A / (2 pi N)``, the largest stable step
                        (the same for every scheme)
amplification           ``R(z)``, the factor by which one step of a scheme
                        multiplies a heat eigenmode

HeatOptions             the options of the heat flow: defaults, help and checks
MCFOptions              the options of the mean curvature flow

``fit_sdf``, ``SDFFitReport`` and ``project_to_zero_set`` (a SphericalNeuralSurface on the zero
set of a signed distance function) live in :mod:`sns_np.surface` and are importable from here
too.

The equations are mapped to the code, and the accuracy measured, in ``docs/flows.md``.
"""

from ._common import SCHEMES, StabilityWarning, amplification, stability_limit
from .heat import HEAT_DEFAULTS, HeatFlowResult, HeatOptions, ModalField, heat_flow
from .mcf import MCF_DEFAULTS, MCFOptions, MeanCurvatureFlowResult, mean_curvature_flow
from .sdf import SDFFitReport, fit_sdf, project_to_zero_set  # noqa: F401  (from surface)

__all__ = ["heat_flow", "HeatFlowResult", "HeatOptions", "ModalField", "HEAT_DEFAULTS",
           "mean_curvature_flow", "MeanCurvatureFlowResult", "MCFOptions", "MCF_DEFAULTS",
           "StabilityWarning",
           "stability_limit", "amplification", "SCHEMES"]
