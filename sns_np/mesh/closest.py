"""Closest points on a triangle mesh: for each query point, the face and barycentric
coordinates of the nearest point of the (flat) mesh, and its distance.

A k-d tree over sites on the faces proposes the faces of the ``k`` nearest sites; the exact
point-triangle distance picks among them. Every face carries enough sites (the centroids of a
regular subdivision) that each of its points lies within ``rho`` of one of them, so a face
whose sites all lie beyond the best distance found plus ``rho`` cannot be closer: the answer is
exact whenever the ``k``-th site is that far, and the few points where it is not are asked
again with four times as many sites, until it is.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._arrays import as_mesh
from .equalise import _subtriangle_centroids

__all__ = ["ClosestPoint"]


@njit(cache=True, fastmath=False)
def _closest_on_triangle(p, a, b, c):
    """Barycentric coordinates (of a, b, c) of the point of triangle abc nearest to p: the
    Voronoi regions of the corners, then of the edges, then the interior."""
    ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    ac0, ac1, ac2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    ap0, ap1, ap2 = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bp0, bp1, bp2 = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:             # edge ab
        t = d1 / (d1 - d3)
        return 1.0 - t, t, 0.0
    cp0, cp1, cp2 = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:             # edge ac
        t = d2 / (d2 - d6)
        return 1.0 - t, 0.0, t
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:   # edge bc
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - t, t
    s = 1.0 / (va + vb + vc)                               # interior
    v, w = vb * s, vc * s
    return 1.0 - v - w, v, w


@njit(cache=True)
def _nearest_among(X, V, F, cand, face, beta, d2):
    """For each row of X, the nearest point on the faces ``cand[i]`` (-1 entries skipped).
    Serial: a fit calls it from the engine's threads, one chunk each (numba's parallel
    layers are not all safe to enter from several threads at once)."""
    for i in range(X.shape[0]):
        best = np.inf
        for j in range(cand.shape[1]):
            f = cand[i, j]
            if f < 0:
                continue
            a, b, c = V[F[f, 0]], V[F[f, 1]], V[F[f, 2]]
            u, v, w = _closest_on_triangle(X[i], a, b, c)
            e = 0.0
            for k in range(3):
                y = u * a[k] + v * b[k] + w * c[k] - X[i, k]
                e += y * y
            if e < best:
                best = e
                face[i] = f
                beta[i, 0], beta[i, 1], beta[i, 2] = u, v, w
        d2[i] = best


class ClosestPoint:
    """Nearest points of a triangle mesh, exact (see the module's note).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    k : int
        Sites (so faces) proposed per query at first; more: fewer repeated queries.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> face, beta, d = ClosestPoint(V, F).query([[0.0, 0.0, 2.0], [0.1, 0.2, 0.3]])
    >>> np.round(d, 3).tolist()                 # 1 outside the unit sphere; inside, the polyhedron
    [1.0, 0.611]
    >>> bool(np.allclose(beta.sum(axis=1), 1.0))
    True
    """

    def __init__(self, V, F, k: int = 8):
        from scipy.spatial import cKDTree
        V, F = as_mesh(V, F)
        self.V = np.ascontiguousarray(V, dtype=np.float64)
        self.F = np.ascontiguousarray(F, dtype=np.int64)
        T = self.V[self.F]
        radius = np.linalg.norm(T - T.mean(axis=1)[:, None], axis=2).max(axis=1)
        # rho: the median face's reach; a larger face is cut into 4^l similar pieces, whose
        # reach is 2^-l of its own
        self.rho = float(np.median(radius))
        level = np.ceil(np.log2(np.maximum(radius / self.rho, 1.0))).astype(np.int64)
        sites, owner = [T.mean(axis=1)], [np.arange(len(T))]
        for lev in np.unique(level[level > 0]):
            f = np.flatnonzero(level == lev)
            beta = _subtriangle_centroids(2 ** int(lev))         # (4^l, 3)
            sites.append(np.einsum("sc,fci->fsi", beta, T[f]).reshape(-1, 3))
            owner.append(np.repeat(f, len(beta)))
        # the centroid of a subdivided face is one of its pieces' only when l = 0: keep it
        # anyway (it is a point of the face, and the bound holds for any superset of sites)
        self.owner = np.concatenate(owner)
        self.tree = cKDTree(np.concatenate(sites))
        self.k = int(min(k, len(self.owner)))

    def query(self, X, exact: bool = True):
        """Nearest mesh points of ``X``.

        Parameters
        ----------
        X : (n, 3) float array
        exact : bool
            False: the best of the ``k`` proposed faces, with no check that a face beyond them
            is closer (about three times faster; a fit's targets need no more).

        Returns
        -------
        face : (n,) int array
        beta : (n, 3) float array, barycentric coordinates in ``F[face]``
        distance : (n,) float array

        Examples
        --------
        >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
        >>> face, beta, d = ClosestPoint(V, F).query([[0.2, 0.2, -1.0]])
        >>> int(face[0]), np.round(beta[0], 2).tolist(), float(d[0])   # below face 0
        (0, [0.6, 0.2, 0.2], 1.0)
        """
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64))
        if X.ndim != 2 or X.shape[1] != 3:
            raise ValueError(f"ClosestPoint.query expects points of shape (n, 3), "
                             f"got {X.shape}")
        if not np.all(np.isfinite(X)):
            raise ValueError("ClosestPoint.query: the points contain NaN or infinity")
        face = np.empty(len(X), dtype=np.int64)
        beta = np.empty((len(X), 3))
        d2 = np.empty(len(X))
        todo, k = np.arange(len(X)), self.k
        while todo.size:
            dc, site = self.tree.query(X[todo], k=k)
            dc, site = np.reshape(dc, (todo.size, k)), np.reshape(site, (todo.size, k))
            cand = self.owner[np.asarray(site, dtype=np.int64)]
            face[todo], beta[todo], d2[todo] = self._among(X[todo], cand)
            if not exact or k == len(self.owner):
                break
            # unsure: a face with no site among the k could still be within reach
            todo = todo[dc[:, -1] < np.sqrt(d2[todo]) + self.rho]
            k = min(4 * k, len(self.owner))
        return face, beta, np.sqrt(d2)

    def _among(self, X, cand):
        X = np.ascontiguousarray(X)
        cand = np.ascontiguousarray(cand)
        face = np.empty(len(X), dtype=np.int64)
        beta = np.empty((len(X), 3))
        d2 = np.empty(len(X))
        _nearest_among(X, self.V, self.F, cand, face, beta, d2)
        return face, beta, d2
