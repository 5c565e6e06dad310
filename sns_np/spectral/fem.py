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

from .._validation import check_choice, check_positive_int

__all__ = ["mesh_eigenvalues", "fem_eigenvalues", "richardson"]


def mesh_eigenvalues(V, F, k: int, mass: str = "full", return_vectors: bool = False):
    """The ``k`` smallest non-zero eigenvalues of the cotangent Laplacian of a closed mesh.

    Solves ``-L phi = lambda M phi`` by shift-invert Lanczos (``scipy.sparse.linalg.eigsh``)
    about a small negative shift, and drops the zero eigenvalue of the constants. Uses
    :func:`sns_np.mesh.laplacian_eigenmodes` when the mesh package provides it.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, a closed connected mesh
    k : int, number of non-zero eigenvalues (``k + 1 < n``)
    mass : {"full", "barycentric", "voronoi"}, see :func:`sns_np.mesh.mass_matrix`
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
    k = check_positive_int(k, "k")
    check_choice(mass, "mass", ("full", "barycentric", "voronoi"))
    V = np.asarray(V, dtype=np.float64)
    if k + 2 > V.shape[0]:
        raise ValueError(f"k = {k} eigenvalues need a mesh with more than {k + 2} vertices, "
                         f"got {V.shape[0]}")
    try:  # the mesh package's solver when it has one
        from ..mesh import laplacian_eigenmodes
    except ImportError:
        laplacian_eigenmodes = None
    if laplacian_eigenmodes is not None:
        return laplacian_eigenmodes(V, F, k, mass=mass, return_vectors=return_vectors)
    return _eigenmodes(V, F, k, mass, return_vectors)


def _eigenmodes(V, F, k, mass, return_vectors):
    """Fallback: shift-invert Lanczos on the cotangent pencil (scipy's generalised mode)."""
    import scipy.sparse.linalg as sla

    from ..mesh import cotan_laplacian, mass_matrix, surface_area

    K = -cotan_laplacian(V, F)
    M = mass_matrix(V, F, mass)
    # a shift below 0 keeps K - sigma M positive definite (K is singular on constants)
    sigma = -1e-3 * 4.0 * np.pi / surface_area(V, F)
    v0 = np.ones(V.shape[0])
    lam, phi = sla.eigsh(K.tocsc(), k=k + 1, M=M.tocsc(), sigma=sigma, which="LM", v0=v0)
    order = np.argsort(lam)
    lam, phi = lam[order][1:], phi[:, order][:, 1:]
    return (lam, phi) if return_vectors else lam


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
