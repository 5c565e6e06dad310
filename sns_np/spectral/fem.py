"""Mesh reference: cotangent finite-element eigenvalues, their refinement and extrapolation.

Piecewise-linear finite elements on a triangle mesh: the stiffness matrix is the cotangent
matrix ``-L`` and the mass matrix the consistent Galerkin matrix ``M`` (both from
:mod:`sns_np.mesh`), and the eigenpairs solve ``-L phi = lambda M phi``. For a mesh inscribed
in a smooth surface (an icosphere pushed through the map) the eigenvalues converge like
``h^2``; each icosphere level halves ``h``, so two levels extrapolate (Richardson) to
``(4 lambda_fine - lambda_coarse) / 3``.

References
----------
G. Dziuk, "Finite elements for the Beltrami operator on arbitrary surfaces", Partial
Differential Equations and Calculus of Variations, LNM 1357, 1988.
M. Reuter, F.-E. Wolter and N. Peinecke, "Laplace-Beltrami spectra as 'Shape-DNA' of surfaces
and solids", Computer-Aided Design 38(4), 2006.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_positive_int

__all__ = ["mesh_eigenvalues", "fem_eigenvalues", "richardson"]


def mesh_eigenvalues(V, F, k: int, mass: str = "full", return_vectors: bool = False):
    """The ``k`` smallest non-zero eigenvalues of the cotangent Laplacian of a closed mesh.

    The package's one FEM eigensolver is :func:`sns_np.mesh.laplacian_eigenmodes` (shift-invert
    Lanczos on ``-L phi = lambda M phi``, the zero eigenvalue of the constants dropped); this
    is the same call with ``mass`` and ``return_vectors`` also accepted by position.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, a closed connected mesh
    k : int, number of non-zero eigenvalues (``k + 1 < n``)
    mass : {"full", "lumped", "voronoi"}, see :func:`sns_np.mesh.laplacian_eigenmodes`
        (``"barycentric"``, the :func:`sns_np.mesh.mass_matrix` kind, is the same as
        ``"lumped"``)
    return_vectors : bool, also return the M-orthonormal eigenvectors (n, k)

    Returns
    -------
    lam : (k,) float array, ascending
    phi : (n, k) float array (only with ``return_vectors``)

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> lam = mesh_eigenvalues(V, F, 3)
    >>> bool(np.allclose(lam, 2.0, rtol=0.02))
    True
    """
    from ..mesh import laplacian_eigenmodes

    return laplacian_eigenmodes(V, F, k, mass=mass, return_vectors=return_vectors)


def fem_eigenvalues(surface, k: int, level: int, mass: str = "full") -> np.ndarray:
    """FEM eigenvalues of the icosphere of ``level`` pushed through a surface map.

    Parameters
    ----------
    surface : surface map (``jet(p, 0)``)
    k : int, number of non-zero eigenvalues
    level : int, icosphere level (``10 * 4^level + 2`` vertices)
    mass : see :func:`mesh_eigenvalues`

    Returns
    -------
    (k,) float array

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> lam = fem_eigenvalues(Sphere(), 3, 3)
    >>> bool(np.allclose(lam, 2.0, rtol=0.02))
    True
    """
    from ..mesh import icosphere
    from ..protocol import surface_jet

    P, F = icosphere(check_positive_int(level, "level", minimum=0))
    return mesh_eigenvalues(surface_jet(surface, P, 0), F, k, mass)


def richardson(coarse, fine, order: float = 2.0, ratio: float = 2.0) -> np.ndarray:
    """Richardson extrapolation ``(r^q fine - coarse) / (r^q - 1)`` of an ``h^q`` sequence.

    Examples
    --------
    >>> richardson(np.array([2.4]), np.array([2.1]))   # error 0.4 then 0.1 -> exact 2
    array([2.])
    """
    c = np.asarray(coarse, dtype=np.float64)
    f = np.asarray(fine, dtype=np.float64)
    s = ratio ** order
    return (s * f - c) / (s - 1.0)
