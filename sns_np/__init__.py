"""sns_np: Spherical Neural Surfaces with NumPy, SciPy and Numba.

A genus-0 surface is encoded as a residual softplus MLP ``S: R^3 -> R^3`` whose restriction to
the unit sphere parametrises the surface (Williamson & Mitra, Eurographics 2025). Exact
derivatives of the network give normals, fundamental forms, curvatures, the Laplace-Beltrami
operator, its eigenmodes and geometric flows, all without meshing.

Submodules are imported on first use so that ``import sns_np`` stays fast:

nn         the hand-differentiated residual network and optimisers
geometry   differential quantities and Laplace-Beltrami on any surface map
shapes     analytic surfaces and fields with exact jets
mesh       mesh input, checks, cotangent operators, spherical embedding
sampling   sphere sampling, rejection sampling by area, Monte Carlo integrals
fields     neural scalar fields on the sphere
spectral   Laplace-Beltrami eigenmodes
flows      heat flow, mean curvature flow, SDF fitting
testing    central-difference derivative checks
quadrature deterministic sphere quadrature
options    the options of fits and flows (FitOptions, HeatOptions, MCFOptions)
"""

from __future__ import annotations

import importlib

from ._version import __version__

_SUBMODULES = {
    "nn", "geometry", "shapes", "mesh", "sampling", "fields", "spectral", "flows",
    "testing", "protocol", "errors", "surface", "cli", "quadrature", "demo", "options",
}
_ATTRS = {"SphericalNeuralSurface": "surface"}

__all__ = sorted(_SUBMODULES) + sorted(_ATTRS) + ["__version__"]


def __getattr__(name):
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    if name in _ATTRS:
        return getattr(importlib.import_module(f".{_ATTRS[name]}", __name__), name)
    raise AttributeError(f"module 'sns_np' has no attribute {name!r}")


def __dir__():
    return __all__
