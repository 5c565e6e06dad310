"""Triangles on the unit sphere: orientation, area, distortion and point location.

A spherical mesh ``(Vs, F)`` has unit-vector vertices; its triangle ``f`` is the central
(gnomonic) projection of the flat chord triangle ``a, b, c`` onto the sphere, which is the
geodesic triangle with those corners. A point ``p`` inside it has *gnomonic barycentric
coordinates* ``beta`` with ``p = (beta_0 a + beta_1 b + beta_2 c) / |...|``; the same
coordinates on the surface triangle give the corresponding surface point.
"""

from __future__ import annotations

import numpy as np

from .._validation import as_sphere_points
from ._arrays import as_mesh
from .operators import face_areas

__all__ = [
    "orientation_determinants",
    "spherical_triangle_areas",
    "area_distortion",
    "face_stretch",
    "SphereLocator",
]


def orientation_determinants(Vs, F) -> np.ndarray:
    """``det[a, b, c]`` of every triangle of points on the sphere (> 0: positively oriented).

    Computed as ``a . ((b - a) x (c - a))``, which stays accurate for tiny triangles.

    Parameters
    ----------
    Vs : (n, 3) float array, unit vectors
    F : (m, 3) int array

    Returns
    -------
    det : (m,) float array

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(1)
    >>> bool((orientation_determinants(V, F) > 0).all())
    True
    """
    a, b, c = Vs[F[:, 0]], Vs[F[:, 1]], Vs[F[:, 2]]
    return np.einsum("ij,ij->i", a, np.cross(b - a, c - a))


def spherical_triangle_areas(Vs, F) -> np.ndarray:
    """Signed area of every geodesic triangle on the unit sphere (negative when folded).

    Van Oosterom & Strackee: ``tan(Omega / 2) = det[a, b, c] / (1 + a.b + b.c + c.a)``.

    Parameters
    ----------
    Vs : (n, 3) float array, unit vectors
    F : (m, 3) int array

    Returns
    -------
    Omega : (m,) float array; sums to ``4 pi`` for a fold-free embedding

    References
    ----------
    A. van Oosterom and J. Strackee, "The solid angle of a plane triangle", IEEE Transactions on
    Biomedical Engineering 30(2), 1983.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> bool(np.isclose(spherical_triangle_areas(V, F).sum(), 4 * np.pi))
    True
    """
    a, b, c = Vs[F[:, 0]], Vs[F[:, 1]], Vs[F[:, 2]]
    det = np.einsum("ij,ij->i", a, np.cross(b - a, c - a))
    den = 1.0 + np.einsum("ij,ij->i", a, b) + np.einsum("ij,ij->i", b, c) \
        + np.einsum("ij,ij->i", c, a)
    return 2.0 * np.arctan2(det, den)


def uniform_in_spherical_triangles(A, B, C, rng) -> np.ndarray:
    """One point uniform by area in each geodesic triangle ``(A[i], B[i], C[i])`` of the
    unit sphere.

    Arvo's inversion of the area function: a first uniform number picks the sub-triangle
    ``A B C'`` holding that share of the area (``C'`` on the arc ``A C``), a second one a
    point on the arc ``B C'`` with the density that makes the result uniform.

    Parameters
    ----------
    A, B, C : (n, 3) float arrays, unit vectors; each triangle positively oriented or not,
        non-degenerate (angles away from 0 and pi)
    rng : numpy.random.Generator (two uniform numbers per point)

    Returns
    -------
    p : (n, 3) float array of unit vectors inside the triangles

    References
    ----------
    J. Arvo, "Stratified sampling of spherical triangles", SIGGRAPH 1995.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(1)
    >>> g = np.random.default_rng(0)
    >>> p = uniform_in_spherical_triangles(V[F[:, 0]], V[F[:, 1]], V[F[:, 2]], g)
    >>> p.shape, bool(np.allclose(np.linalg.norm(p, axis=1), 1.0))
    ((80, 3), True)
    """
    A, B, C = (np.asarray(X, dtype=np.float64) for X in (A, B, C))

    def unit(x):
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)

    def corner(P, Q, R):            # the angle at P between the arcs P Q and P R
        return np.arccos(np.clip(dot(unit(Q - dot(P, Q)[:, None] * P),
                                     unit(R - dot(P, R)[:, None] * P)), -1.0, 1.0))

    alpha, beta, gamma = corner(A, B, C), corner(B, C, A), corner(C, A, B)
    share = rng.random(len(A)) * (alpha + beta + gamma - np.pi)     # the sub-triangle's area
    s, t = np.sin(share - alpha), np.cos(share - alpha)
    u = t - np.cos(alpha)
    v = s + np.sin(alpha) * dot(A, B)
    q = np.clip(((v * t - u * s) * np.cos(alpha) - v) / ((v * s + u * t) * np.sin(alpha)),
                -1.0, 1.0)
    Cq = q[:, None] * A + np.sqrt(1.0 - q * q)[:, None] * unit(C - dot(C, A)[:, None] * A)
    z = 1.0 - rng.random(len(A)) * (1.0 - dot(Cq, B))
    p = z[:, None] * B + np.sqrt(np.maximum(1.0 - z * z, 0.0))[:, None] * unit(
        Cq - dot(Cq, B)[:, None] * B)
    return unit(p)


def area_distortion(V, F, Vs) -> np.ndarray:
    """Per-face log area ratio ``log((s_f / sum s) / (A_f / sum A))`` (0: area-preserving).

    Parameters
    ----------
    V : (n, 3) float array, the surface
    F : (m, 3) int array
    Vs : (n, 3) float array, its fold-free spherical embedding

    Returns
    -------
    d : (m,) float array (``-inf`` for a folded or zero-area spherical triangle)

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> float(abs(area_distortion(2 * V, F, V)).max()) < 0.1
    True
    """
    V, F = as_mesh(V, F)
    A = face_areas(V, F)
    s = spherical_triangle_areas(Vs, F)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(np.where(s > 0, s, 0.0) / s.sum()) - np.log(A / A.sum())


class SphereLocator:
    """Point location on a fold-free spherical triangulation.

    Candidates come from a k-d tree on the (normalised) triangle centroids; each candidate is
    tested with its gnomonic barycentric coordinates, computed in a per-triangle frame
    (corner ``a``, unit normal ``n``, dual edge basis) so that they stay accurate for tiny
    triangles. Points not found among the ``k`` nearest centroids are retried with 4x more
    candidates, and finally against every triangle, so every point is located.

    Parameters
    ----------
    Vs : (n, 3) float array, unit vectors
    F : (m, 3) int array, every triangle positively oriented (``det[a, b, c] > 0``)

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> loc = SphereLocator(V, F)
    >>> c = V[F[7]].mean(axis=0, keepdims=True)
    >>> f, beta = loc.locate(c / np.linalg.norm(c))
    >>> int(f[0]), np.round(beta, 6).tolist()
    (7, [[0.333333, 0.333333, 0.333333]])
    """

    def __init__(self, Vs, F):
        from scipy.spatial import cKDTree

        Vs, F = as_mesh(Vs, F, V_name="Vs")
        self.F = F
        a, b, c = Vs[F[:, 0]], Vs[F[:, 1]], Vs[F[:, 2]]
        u, w = b - a, c - a
        N = np.cross(u, w)
        det = np.linalg.norm(N, axis=1)
        if not (det > 0).all():
            f = int(np.argmin(det))
            raise ValueError(f"spherical triangle {f} is degenerate; SphereLocator needs a "
                             "fold-free embedding")
        n = N / det[:, None]
        self._a, self._n = a, n
        # dual basis of (u, w) in the triangle plane: ut . u = 1, ut . w = 0, ...
        self._ut = np.cross(w, n) / det[:, None]
        self._wt = np.cross(n, u) / det[:, None]
        cen = a + b + c
        self._tree = cKDTree(cen / np.linalg.norm(cen, axis=1, keepdims=True))

    def barycentric(self, p, faces) -> np.ndarray:
        """Gnomonic barycentric coordinates of points ``p`` (k, 3) in triangles ``faces`` (k,).

        Coordinates sum to 1; all are >= 0 exactly when ``p`` lies in the triangle (for a point
        in the opposite hemisphere of the triangle they are returned as ``-inf``).

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> V, F = icosphere(2)
        >>> loc = SphereLocator(V, F)
        >>> beta = loc.barycentric(V[F[[3]]][:, 0], np.array([3]))   # the first corner of face 3
        >>> beta.round(6)
        array([[1., 0., 0.]])
        """
        a, n = self._a[faces], self._n[faces]
        d = p - a
        pn = np.einsum("ij,ij->i", p, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            d -= (np.einsum("ij,ij->i", d, n) / pn)[:, None] * p
        b1 = np.einsum("ij,ij->i", d, self._ut[faces])
        b2 = np.einsum("ij,ij->i", d, self._wt[faces])
        beta = np.stack([1.0 - b1 - b2, b1, b2], axis=1)
        beta[~(pn > 0)] = -np.inf
        return beta

    def _search(self, p, k):
        k = min(k, self.F.shape[0])
        _, cand = self._tree.query(p, k=k)
        cand = cand.reshape(p.shape[0], k)
        best_f = np.empty(p.shape[0], dtype=np.int64)
        best_b = np.empty((p.shape[0], 3))
        best_m = np.full(p.shape[0], -np.inf)
        active = np.arange(p.shape[0])
        for j in range(k):
            # a point inside one triangle is inside no other (up to shared edges): stop there
            f = cand[active, j]
            beta = self.barycentric(p[active], f)
            m = beta.min(axis=1)
            better = m > best_m[active]
            idx = active[better]
            best_f[idx], best_b[idx], best_m[idx] = f[better], beta[better], m[better]
            active = active[best_m[active] < 0]
            if not active.size:
                break
        return best_f, best_b, best_m

    def locate(self, p, *, k: int = 8, tol: float = 1e-12):
        """Triangle and gnomonic barycentric coordinates of each point.

        Parameters
        ----------
        p : (q, 3) float array, unit vectors
        k : int
            Initial number of candidate triangles per point.
        tol : float
            A point counts as inside when its smallest coordinate is ``>= -tol``; coordinates
            are then clipped to ``[0, 1]`` and renormalised.

        Returns
        -------
        face : (q,) int array
        beta : (q, 3) float array, non-negative, rows sum to 1

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> V, F = icosphere(2)
        >>> from sns_np.sampling import uniform_sphere
        >>> p = uniform_sphere(1000, rng=0)
        >>> f, beta = SphereLocator(V, F).locate(p)
        >>> f.shape, beta.shape, bool((beta >= 0).all()), bool(np.allclose(beta.sum(axis=1), 1))
        ((1000,), (1000, 3), True, True)
        """
        p = as_sphere_points(p, "p")
        face, beta, m = self._search(p, k)
        todo = np.flatnonzero(m < -tol)
        kk, m_all = k, self.F.shape[0]
        while todo.size:
            kk *= 4
            brute = kk >= min(1024, m_all)
            f2, b2, m2 = self._brute(p[todo]) if brute else self._search(p[todo], kk)
            better = m2 > m[todo]
            face[todo[better]], beta[todo[better]], m[todo[better]] = (
                f2[better], b2[better], m2[better])
            todo = todo[m[todo] < -tol]
            if brute:
                break                   # left: points on no triangle within tol (rounding)
        beta = np.clip(beta, 0.0, None)
        beta /= beta.sum(axis=1, keepdims=True)
        return face, beta

    def _brute(self, p):
        m_all = self.F.shape[0]
        best_f = np.zeros(p.shape[0], dtype=np.int64)
        best_b = np.zeros((p.shape[0], 3))
        best_m = np.full(p.shape[0], -np.inf)
        for i in range(p.shape[0]):
            beta = self.barycentric(np.repeat(p[i:i + 1], m_all, axis=0), np.arange(m_all))
            f = int(np.argmax(beta.min(axis=1)))
            best_f[i], best_b[i], best_m[i] = f, beta[f], beta[f].min()
        return best_f, best_b, best_m


def face_stretch(V, F, Vs) -> np.ndarray:
    """Largest singular value, per face, of the linear map from sphere triangle to surface.

    Both sides are normalised to total area ``4 pi``, so the value is 1 everywhere for an
    isometry of the unit sphere; large values flag faces where the surface is stretched
    relative to its image on the sphere (a network fitted on the sphere must vary fast there).
    The sphere side is the chord triangle.

    Parameters
    ----------
    V : (n, 3) float array, the surface
    F : (m, 3) int array
    Vs : (n, 3) float array, a fold-free spherical embedding

    Returns
    -------
    sigma : (m,) float array

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> s = face_stretch(V * [1.0, 1.0, 2.0], F, V)
    >>> bool(s.min() > 0.7 and s.max() < 2.0)
    True
    """
    V, F = as_mesh(V, F)

    def frames(X):
        a, b = X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]
        e1 = a / np.linalg.norm(a, axis=1, keepdims=True)
        n = np.cross(a, b)
        e2 = np.cross(n / np.linalg.norm(n, axis=1, keepdims=True), e1)
        # 2 x 2 matrix whose columns are the edge vectors a, b in the frame (e1, e2)
        return np.stack([np.stack([np.einsum("ij,ij->i", a, e1), np.zeros(len(F))], 1),
                         np.stack([np.einsum("ij,ij->i", b, e1),
                                   np.einsum("ij,ij->i", b, e2)], 1)], axis=2)

    A_surf = face_areas(V, F).sum()
    A_sph = face_areas(Vs, F).sum()
    T = frames(V) * np.sqrt(4 * np.pi / A_surf)
    S = frames(Vs) * np.sqrt(4 * np.pi / A_sph)
    J = T @ np.linalg.inv(S)
    return np.linalg.svd(J, compute_uv=False)[:, 0]
