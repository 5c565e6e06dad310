"""Fitting to a signed distance function lives in :mod:`sns_np.surface.sdf` (a fit, and
``surface`` must not import ``flows``); these names stay importable from here."""

from ..surface.sdf import SDFFitReport, fit_sdf, project_to_zero_set

__all__ = ["SDFFitReport", "fit_sdf", "project_to_zero_set"]
