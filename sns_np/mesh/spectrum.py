"""Finite-element Laplace-Beltrami eigenvalues of a mesh (the reference for the spectral part).

The weak eigenproblem of ``Delta phi = -lambda phi`` with piecewise-linear elements is the
generalised symmetric problem ``-L phi = lambda M phi`` (``L`` the cotangent stiffness,
negative semi-definite; ``M`` the mass matrix, full or lumped). It is solved with
``scipy.sparse.linalg.eigsh`` in shift-invert mode about a small negative shift ``sigma``, so
that ``-L - sigma M`` is positive definite and the eigenvalues nearest zero converge first.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from .._validation import check_choice, check_positive_int
from ._arrays import as_mesh
from .operators import cotan_laplacian, face_areas, mass_matrix

__all__ = ["laplacian_eigenmodes", "eigenvalues"]

#: ``mass=`` of the solver -> kind of :func:`sns_np.mesh.mass_matrix`. The diagonal
#: barycentric mass is called "lumped" here (the FEM name); "barycentric", the mass-matrix kind,
#: is accepted as the same thing so that either name works in either place.
_MASS = {"full": "full", "lumped": "barycentric", "barycentric": "barycentric",
         "voronoi": "voronoi"}


def _smallest_generalized(A, M, k, sigma):
    """Eigenpairs of ``A x = lam M x`` nearest ``sigma`` (below the spectrum), M-orthonormal.

    With the factorisation ``A - sigma M = C C^T`` (sparse LDL^T from SuperLU with a symmetric
    ordering and no pivoting: ``C = P^T L D^(1/2)``), the pencil becomes the standard symmetric
    problem ``C^-1 M C^-T y = mu y`` with ``mu = 1 / (lam - sigma)`` and ``x = C^-T y``, whose
    largest ``mu`` ARPACK finds in its plain mode (its generalised mode is several times slower
    here).
    """
    n = A.shape[0]
    lu = spla.splu((A - sigma * M).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    Lf, Uf, pr = lu.L.tocsr(), lu.U.tocsr(), lu.perm_r
    d = Uf.diagonal()
    if not (np.array_equal(lu.perm_r, lu.perm_c) and (d > 0).all()):  # pragma: no cover
        OPinv = spla.LinearOperator((n, n), matvec=lu.solve, dtype=np.float64)
        return spla.eigsh(A, k=k, M=M, sigma=sigma, which="LM", OPinv=OPinv,
                          v0=np.random.default_rng(0).standard_normal(n))
    sq = np.sqrt(d)

    def c_inv(w):                       # C^-1 w = D^-1/2 L^-1 P w
        z = np.empty_like(w)
        z[pr] = w
        return spla.spsolve_triangular(Lf, z, lower=True, unit_diagonal=True) / (
            sq if w.ndim == 1 else sq[:, None])

    def c_inv_t(y):                     # C^-T y = P^T L^-T D^-1/2 y = P^T U^-1 D^1/2 y
        v = spla.spsolve_triangular(Uf, y * (sq if y.ndim == 1 else sq[:, None]), lower=False)
        return v[pr]

    S = spla.LinearOperator((n, n), matvec=lambda y: c_inv(M @ c_inv_t(y)), dtype=np.float64)
    mu, Y = spla.eigsh(S, k=k, which="LA", v0=np.random.default_rng(0).standard_normal(n))
    return sigma + 1.0 / mu, c_inv_t(Y) / np.sqrt(mu)


def laplacian_eigenmodes(V, F, k: int, *, mass: str = "full", return_vectors: bool = False):
    """The ``k`` lowest non-zero Laplace-Beltrami eigenvalues (and eigenfunctions) of a mesh.

    Solves ``-L phi = lambda M phi`` for the ``k + 1`` smallest eigenvalues and drops the first,
    the zero eigenvalue of the constant function (the mesh must be connected, as
    :func:`sns_np.mesh.check` ensures).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    k : int
        Number of non-zero eigenvalues, ``1 <= k <= n - 2``.
    mass : {"full", "lumped", "voronoi"}
        Consistent (Galerkin) mass matrix, which converges from above for the sphere, or the
        diagonal barycentric ("lumped"; ``"barycentric"`` is accepted as the same) or
        mixed-Voronoi one.
    return_vectors : bool
        Also return the eigenfunctions.

    Returns
    -------
    lam : (k,) float array, ascending, positive (DESIGN: ``Delta phi = -lambda phi``)
    phi : (n, k) float array, only with ``return_vectors``; ``M``-orthonormal,
        ``phi.T @ M @ phi = I``

    References
    ----------
    M. Reuter, F.-E. Wolter and N. Peinecke, "Laplace-Beltrami spectra as 'Shape-DNA' of
    surfaces and solids", Computer-Aided Design 38(4), 2006.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> lam = laplacian_eigenmodes(V, F, 8)       # unit sphere: 2 (x3), 6 (x5)
    >>> [round(float(x), 1) for x in lam]
    [2.0, 2.0, 2.0, 6.1, 6.1, 6.1, 6.1, 6.1]
    """
    V, F = as_mesh(V, F)
    k = check_positive_int(k, "k")
    check_choice(mass, "mass", tuple(_MASS))
    n = V.shape[0]
    if k > n - 2:
        raise ValueError(f"k must be <= n - 2 = {n - 2} for a mesh with {n} vertices, got {k}")
    L = cotan_laplacian(V, F)
    M = mass_matrix(V, F, _MASS[mass])
    # eigenvalues scale like 1 / area; shift below zero by a small fraction of the unit sphere's
    # first eigenvalue rescaled to this area
    sigma = -0.05 * 4.0 * np.pi / face_areas(V, F).sum()
    # Lanczos can miss a copy of a repeated eigenvalue at the edge of the wanted set (the
    # icosphere's 5-fold 6.07 with k = 8 came back as 6.07 x 4 and 12.2): ask for a margin
    # of extra pairs and keep the smallest k + 1
    want = max(k + 1, min(n - 1, k + 1 + max(4, (k + 1) // 2)))
    lam, phi = _smallest_generalized((-L).tocsc(), M.tocsc(), want, sigma)
    order = np.argsort(lam)[:k + 1]
    lam, phi = lam[order][1:], phi[:, order][:, 1:]
    return (lam, phi) if return_vectors else lam


def eigenvalues(V, F, k: int, *, mass: str = "full") -> np.ndarray:
    """Shorthand for ``laplacian_eigenmodes(V, F, k, mass=mass)`` (eigenvalues only).

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> eigenvalues(*icosphere(3), 3).round(2)          # unit sphere: 2, 2, 2
    array([2.01, 2.01, 2.01])
    """
    return laplacian_eigenmodes(V, F, k, mass=mass)
