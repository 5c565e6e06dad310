"""Area balancing by stretch-energy minimisation (Yueh, Lin, Wu & Yau).

The stretch energy of a map ``f`` from the surface to the sphere is
``E_S(f) = sum_tau |f(tau)|^2 / |tau|``, the Dirichlet energy with every triangle weighted by
its area ratio ``sigma_tau = |f(tau)| / |tau|``; for a fixed total area it is smallest exactly
for equiareal maps. It is minimised by a fixed-point iteration: with the weights frozen,
``E_S`` is a quadratic form ``f^T L_S f`` (the cotangent Laplacian of the *surface*, each
triangle's entries multiplied by its weight), minimised on the sphere by alternating
hemispheres: the vertices of the southern hemisphere are re-solved in the stereographic plane
from the north pole with the others held fixed, then the northern ones from the south pole.

Three changes are ours. Negative cotangents (obtuse surface angles) are clipped to zero, so
that every half-step is a Tutte-type solve with positive weights, whose boundary (the fixed
hemisphere, near the unit circle in the stereographic plane) is nearly convex: folds are rare and
repaired locally. The weights are updated multiplicatively and damped,
``w_tau <- w_tau sigma_tau^gamma``, so that they converge to the weights of the fixed point
rather than oscillate; and a step is accepted only if it leaves no fold (after local repair)
and lowers the spread of the log area ratios, otherwise ``gamma`` is halved and the step
retried from the best state. The result is therefore always fold-free and never worse than the
input.

References
----------
M.-H. Yueh, W.-W. Lin, C.-T. Wu and S.-T. Yau, "A novel stretch energy minimization algorithm
for equiareal parameterizations", Journal of Scientific Computing 78, 2019.

M.-H. Yueh, T. Li, W.-W. Lin and S.-T. Yau, "A novel algorithm for volume-preserving
parameterizations of 3-manifolds", SIAM Journal on Imaging Sciences 12(2), 2019 (the spherical,
two-hemisphere form of the iteration).

W. T. Tutte, "How to draw a graph", Proceedings of the London Mathematical Society 13, 1963.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .foldrepair import FoldRepair
from .operators import _cotangents, face_areas
from .spherical import orientation_determinants, spherical_triangle_areas

__all__ = ["minimise_stretch"]


def _weighted_laplacian(C, F, n, w):
    """Positive semi-definite ``L_S``: cotangent weights of each face times its weight."""
    i = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    j = np.concatenate([F[:, 2], F[:, 0], F[:, 1]])
    c = 0.5 * (C * w[:, None]).T.ravel()
    W = sp.csr_matrix((np.concatenate([c, c]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                      shape=(n, n))
    return (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()


def _half_step(P, L, pole):
    """Re-solve the hemisphere opposite ``pole`` (+1: north) in the stereographic plane."""
    z = pole * P[:, 2]
    h = P[:, :2] / (1.0 - z)[:, None]
    free, fixed = np.flatnonzero(z < 0), np.flatnonzero(z >= 0)
    if free.size == 0:
        return P
    Lf = L[free]
    lu = spla.splu(Lf[:, free].tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    h[free] = lu.solve(-np.asarray(Lf[:, fixed] @ h[fixed]))
    r2 = (h ** 2).sum(axis=1, keepdims=True)
    Q = np.hstack([2.0 * h, pole * (r2 - 1.0)]) / (1.0 + r2)
    return Q / np.linalg.norm(Q, axis=1, keepdims=True)


def _spread(A, P, F):
    s = spherical_triangle_areas(P, F)
    if not (s > 0).all():
        return np.inf
    return float(np.log((s / s.sum()) / A).std())


def minimise_stretch(V, F, Vs, *, iterations: int = 30, gamma: float = 0.5,
                     tolerance: float = 1.1, repair: FoldRepair | None = None, seed: int = 0):
    """Move a fold-free spherical embedding towards an equiareal one (stretch energy).

    Parameters
    ----------
    V : (n, 3) float array, the surface
    F : (m, 3) int array
    Vs : (n, 3) float array, a fold-free spherical embedding (e.g. conformal)
    iterations : int
        Weight updates (each one solves both hemispheres).
    gamma : float in (0, 1]
        Damping exponent of the multiplicative weight update.
    tolerance : float >= 1
        A step is accepted while the spread stays below ``tolerance`` times the best so far
        (the stretch energy, not the spread, is what decreases); the best state is returned.
    repair : FoldRepair, optional
        Fold repair of this mesh (reused for its cached weights).
    seed : int
        Seed of the random rotation that keeps vertices away from the projection poles.

    Returns
    -------
    Vs : (n, 3) float array, fold-free unit vectors, log-area-ratio spread no larger than
        the input's
    info : dict
        ``accepted`` steps, final ``gamma`` and ``spread`` (std of the log area ratios).

    References
    ----------
    M.-H. Yueh, W.-W. Lin, C.-T. Wu and S.-T. Yau, "A novel stretch energy minimization
    algorithm for equiareal parameterizations", Journal of Scientific Computing 78, 2019.

    Examples
    --------
    >>> from sns_np.mesh import area_distortion, icosphere
    >>> V, F = icosphere(3)
    >>> X = V * [1.0, 1.0, 3.0]                  # radial projection crowds the poles' area
    >>> Vs, info = minimise_stretch(X, F, V, iterations=20)
    >>> round(float(area_distortion(X, F, V).std()), 2), round(info["spread"], 2)
    (0.26, 0.02)
    """
    if repair is None:
        repair = FoldRepair(V, F)
    A = face_areas(V, F)
    A = A / A.sum()
    C, _ = _cotangents(np.asarray(V, dtype=np.float64), F)
    C = np.maximum(C, 0.0)              # positive weights: each half-step is a Tutte solve
    n = Vs.shape[0]
    # a random rotation keeps every vertex off the poles of the stereographic projections
    Qr, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    P = np.asarray(Vs, dtype=np.float64) @ Qr
    best, best_spread = P.copy(), _spread(A, P, F)
    cur, cur_w = P, np.ones(F.shape[0])
    w_best = cur_w
    accepted = 0
    for _ in range(iterations):
        s = spherical_triangle_areas(cur, F)
        w = cur_w * ((s / s.sum()) / A) ** gamma
        L = _weighted_laplacian(C, F, n, w)
        P = _half_step(_half_step(cur, L, +1), L, -1)
        if (orientation_determinants(P, F) <= 0).any():
            repair(P, max_rounds=10)
        spread = _spread(A, P, F) if not (orientation_determinants(P, F) <= 0).any() else np.inf
        if spread < tolerance * best_spread:
            # the energy, not the spread, decreases monotonically: allow small detours
            cur, cur_w = P, w
            accepted += 1
            if spread < best_spread:
                best, best_spread = P, spread
        else:
            gamma *= 0.5
            cur, cur_w = best, w_best if accepted else np.ones(F.shape[0])
            if gamma < 0.05:
                break
        if spread <= best_spread:
            w_best = w
    return best @ Qr.T, {"accepted": accepted, "gamma": gamma, "spread": best_spread}
