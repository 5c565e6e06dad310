"""Rayleigh-Ritz eigenmodes in a spherical-harmonic basis pulled back through the surface map.

The trial space is ``V_L = span{Y_lm o S^-1 : l <= L}``: fields on the surface whose values at
``S(p)`` are spherical harmonics of ``p`` (the field convention ``h(S(p)) = g(p)`` of DESIGN.md).
The Galerkin matrices of the variational problem ``min Q(h)`` (paper Eq. 20)

    A_jk = integral over S of grad_S Y_j . grad_S Y_k dA
         = integral over S^2 of (R^T grad Y_j)^T I^-1 (R^T grad Y_k) sqrt(det I) dsigma,
    M_jk = integral over S of Y_j Y_k dA = integral over S^2 of Y_j Y_k sqrt(det I) dsigma,

are assembled with the product Gauss rule of :mod:`sns_np.quadrature`, and the generalized
symmetric eigenproblem ``A c = lambda M c`` is solved with :func:`scipy.linalg.eigh`. By the
min-max principle the Ritz values are upper bounds of the exact eigenvalues that decrease
monotonically in ``L``; for a smooth (analytic) map they converge faster than any power of
``L``. On the unit sphere the basis contains the exact eigenfunctions, so ``L >= 3`` gives
``l(l+1)`` for ``l <= 3`` to round-off.

Because ``V_{L-2}`` is a subspace of ``V_L`` and the basis is ordered by degree, the matrices
of degree ``L - 2`` are the leading blocks of those of degree ``L``: the convergence indicator
(the relative change of the eigenvalues from ``L - 2`` to ``L``) costs one more small
eigensolve.

References
----------
W. Ritz, "Über eine neue Methode zur Lösung gewisser Variationsprobleme der mathematischen
Physik", J. reine angew. Math. 135, 1909.
B. N. Parlett, "The Symmetric Eigenvalue Problem", SIAM, 1998 (chapter 11, Rayleigh-Ritz).
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np
import scipy.linalg

from .._progress import Progress
from .._validation import check_positive_float, check_positive_int
from ..quadrature import sphere_quadrature
from ..sampling import surface_geometry
from .harmonics import HarmonicField, evaluate_expansions, n_harmonics, real_sh
from .result import EigenResult

__all__ = ["assemble", "ritz_eigenmodes", "default_degree"]

#: points per chunk of the assembly (bounds the (chunk, (L+1)^2, 3) gradient array)
CHUNK = 2048


def default_degree(k: int) -> int:
    """Starting degree for ``k`` modes: about twice the degree of mode ``k`` on a sphere.

    Examples
    --------
    >>> default_degree(1), default_degree(10), default_degree(50)
    (5, 9, 17)
    """
    return max(4, int(math.ceil(2.0 * math.sqrt(k + 1))) + 2)


def quadrature_size(L: int, margin: int | None = None) -> int:
    """``n_theta`` of the assembly rule for degree ``L``: ``L + 1 + margin``.

    Products ``Y_j Y_k`` have degree ``2 L``; the rule with ``n_theta`` Gauss nodes in ``z``
    and ``2 n_theta`` in ``phi`` integrates them exactly, and the margin (default
    ``max(16, L // 2)``) resolves the smooth weights ``sqrt(det I)`` and ``I^-1``.
    """
    margin = max(16, L // 2) if margin is None else check_positive_int(margin, "margin", 0)
    return L + 1 + margin


def assemble(surface, L: int, n_theta: int | None = None, chunk: int = CHUNK):
    """Stiffness and mass matrices of the harmonics of degree ``<= L`` on the surface.

    Parameters
    ----------
    surface : surface map
    L : int >= 1, maximum degree
    n_theta : int, optional, Gauss nodes in ``z`` (default :func:`quadrature_size`)
    chunk : int, points per block

    Returns
    -------
    A, M : ((L+1)^2, (L+1)^2) float arrays, symmetric: the stiffness (Dirichlet energy)
        matrix ``A`` (``K`` is kept for Gaussian curvature) and the mass matrix ``M``, positive
        definite
    area : float, ``M[0, 0] * 4 pi`` (the quadrature area)
    n_points : int, quadrature nodes used

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> A, M, area, _ = assemble(Sphere(), 2)
    >>> bool(np.allclose(M, np.eye(9))), bool(np.allclose(np.diag(A), [0, 2, 2, 2, 6, 6, 6, 6, 6]))
    (True, True)
    """
    L = check_positive_int(L, "L")
    nt = quadrature_size(L) if n_theta is None else check_positive_int(n_theta, "n_theta")
    p, v = sphere_quadrature(nt)
    _, R, Iinv, d = surface_geometry(surface, p)
    W = v * d
    # I^-1 = U U^T (2 x 2 Cholesky), so that (R^T g)^T I^-1 (R^T g) = |U^T R^T g|^2
    a = np.sqrt(Iinv[:, 0, 0])
    b = Iinv[:, 1, 0] / a
    c = np.sqrt(np.maximum(Iinv[:, 1, 1] - b * b, 0.0))
    nb = n_harmonics(L)
    A = np.zeros((nb, nb))
    M = np.zeros((nb, nb))
    for lo in range(0, p.shape[0], chunk):
        sl = slice(lo, min(lo + chunk, p.shape[0]))
        Y, G = real_sh(p[sl], L, 1)
        T = np.einsum("kjx,kxa->kja", G, R[sl])  # tangential components (c, nb, 2)
        Z0 = a[sl, None] * T[:, :, 0] + b[sl, None] * T[:, :, 1]
        Z1 = c[sl, None] * T[:, :, 1]
        w = W[sl, None]
        M += Y.T @ (w * Y)
        A += Z0.T @ (w * Z0) + Z1.T @ (w * Z1)
    A = 0.5 * (A + A.T)
    M = 0.5 * (M + M.T)
    return A, M, float(W.sum()), int(p.shape[0])


def _solve(A, M, L, k):
    nb = n_harmonics(L)
    lam, C = scipy.linalg.eigh(A[:nb, :nb], M[:nb, :nb], subset_by_index=[0, k])
    return lam, C


def _relative_change(new, old):
    return float(np.max(np.abs(new - old) / np.maximum(np.abs(new), 1e-300)))


def ritz_eigenmodes(surface, k: int, *, L: int | None = None, tol: float = 1e-6,
                    L_max: int = 40, n_theta: int | None = None, progress: bool = False):
    """The ``k`` smallest non-zero Laplace-Beltrami eigenpairs by Rayleigh-Ritz.

    Parameters
    ----------
    surface : surface map
    k : int >= 1
    L : int, optional
        Maximum harmonic degree. Default: automatic, starting from :func:`default_degree`
        and raised (by half, then by at least 4) until the indicator is below ``tol``.
    tol : float, target of the convergence indicator (automatic ``L`` only)
    L_max : int, largest degree tried automatically
    n_theta : int, optional, quadrature size (default :func:`quadrature_size` of ``L``)
    progress : bool, print one line per degree tried

    Returns
    -------
    EigenResult with :class:`~sns_np.spectral.harmonics.HarmonicField` eigenfunctions,
    ``L2``-normalised on the surface, sign fixed so that the largest coefficient is positive;
    ``convergence`` is the indicator at the returned degree and ``info`` holds ``L``,
    ``n_points``, ``history`` (degree, indicator) and the eigenvalues at ``L - 2``.

    Raises
    ------
    ValueError
        If ``k`` exceeds what the basis can resolve: ``k > (L+1)^2 - 1`` for a given ``L``, or
        ``default_degree(k) > L_max``.
    DegenerateMapError
        If the map's Jacobian is (near-)singular at a quadrature node.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> res = ritz_eigenmodes(Ellipsoid(1.0, 1.0, 1.0), 8)
    >>> res.eigenvalues.round(6)
    array([2., 2., 2., 6., 6., 6., 6., 6.])
    """
    t0 = time.perf_counter()
    k = check_positive_int(k, "k")
    tol = check_positive_float(tol, "tol")
    L_max = check_positive_int(L_max, "L_max")
    if L is not None:
        L = check_positive_int(L, "L")
        if k > n_harmonics(L) - 1:
            raise ValueError(
                f"k = {k} modes cannot be resolved by harmonics of degree <= L = {L} "
                f"({n_harmonics(L)} functions, at most {n_harmonics(L) - 1} non-constant "
                f"modes); raise L or leave it None (automatic)")
        degrees = [L]
    else:
        L0 = default_degree(k)
        if L0 > L_max:
            raise ValueError(f"k = {k} modes need harmonics of degree about {L0} > L_max = "
                             f"{L_max}; raise L_max or ask for fewer modes")
        degrees = [L0]
    bar = Progress(1, "ritz", enabled=progress)
    history = []
    while True:
        Lc = degrees[-1]
        A, M, area, n_points = assemble(surface, Lc, n_theta)
        lam, C = _solve(A, M, Lc, k)
        Lp = Lc - 2
        if Lp >= 1 and n_harmonics(Lp) - 1 >= k:
            lam_prev = _solve(A, M, Lp, k)[0]
            indicator = _relative_change(lam[1:], lam_prev[1:])
        else:
            lam_prev, indicator = None, math.nan
        history.append((Lc, indicator))
        bar.update(0, force=True, L=Lc, change=f"{indicator:.2e}", points=n_points)
        converged = bool(indicator <= tol)  # False for NaN: nothing to compare with
        if L is not None or converged:
            break
        if Lc >= L_max:
            warnings.warn(f"Rayleigh-Ritz did not converge: the eigenvalues still change by "
                          f"{indicator:.2e} (relative) from degree {Lc - 2} to {Lc} = L_max; "
                          f"raise L_max or pass a larger L", RuntimeWarning, stacklevel=2)
            break
        degrees.append(min(L_max, max(Lc + 4, (3 * Lc) // 2)))
    bar.close()
    # fix signs: largest coefficient positive
    Ck = C[:, 1:]
    piv = np.argmax(np.abs(Ck), axis=0)
    Ck = Ck * np.sign(Ck[piv, np.arange(k)])
    fields = [HarmonicField(Ck[:, i], name=f"mode {i + 1}") for i in range(k)]
    return EigenResult(
        eigenvalues=lam[1:].copy(), eigenfunctions=fields, method="ritz",
        constant_eigenvalue=float(lam[0]), constant_value=1.0 / math.sqrt(area), area=area,
        stderr=None, converged=bool(converged), convergence=indicator,
        seconds=time.perf_counter() - t0,
        info={"L": Lc, "n_points": n_points, "n_basis": n_harmonics(Lc), "history": history,
              "eigenvalues_L_minus_2": None if lam_prev is None else lam_prev[1:].copy(),
              "coefficients": Ck},
        evaluator=lambda p: evaluate_expansions(p, Ck))
