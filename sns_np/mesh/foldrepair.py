"""Local repair of folded triangles in a spherical embedding.

Triangles with ``det[a, b, c] <= 0`` are grouped into regions: their vertices, grown by a few
rings, with any enclosed holes filled, so that each region is a topological disc. Each region
is mapped to the plane by the gnomonic projection about its centre. That projection maps great
circles to straight lines, so a spherical triangle is positively oriented exactly when its
planar image is. The interior vertices are then placed by Tutte's barycentric method, with the
mean-value weights of the *surface* mesh (positive on every edge, Floater 2003) and the region
boundary held fixed, and projected back to the sphere. If the region's boundary is convex, this
is guaranteed fold-free (Tutte 1963; Floater 2003). Otherwise a region that still folds is grown
by one more ring and solved again.

References
----------
W. T. Tutte, "How to draw a graph", Proceedings of the London Mathematical Society 13, 1963.

M. S. Floater, "Mean value coordinates", Computer Aided Geometric Design 20(1), 2003.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from ._arrays import halfedges, unique_edges
from .errors import EmbeddingError
from .operators import face_areas
from .spherical import orientation_determinants

__all__ = ["FoldRepair", "mean_value_weights", "split_into_discs", "tutte_halves", "tutte_sphere"]


def mean_value_weights(V, F) -> sp.csr_matrix:
    """Row-normalised mean-value weights of a surface mesh: positive on every edge.

    ``w_ij = (tan(alpha_ij / 2) + tan(beta_ij / 2)) / |v_i - v_j|`` with ``alpha_ij`` and
    ``beta_ij`` the angles at ``v_i`` of the two triangles that share edge ``ij``.
    """
    n = V.shape[0]
    P = V[F]
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, l = F[:, k], F[:, (k + 1) % 3], F[:, (k + 2) % 3]
        u = P[:, (k + 1) % 3] - P[:, k]
        v = P[:, (k + 2) % 3] - P[:, k]
        nu, nv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
        # tan(theta / 2) = |u x v| / (|u||v| + u.v), stable for all angles in (0, pi)
        t = np.linalg.norm(np.cross(u, v), axis=1) / (nu * nv + np.einsum("ij,ij->i", u, v))
        rows += [i, i]
        cols += [j, l]
        vals += [t / nu, t / nv]
    W = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(n, n))
    return (sp.diags(1.0 / np.asarray(W.sum(axis=1)).ravel()) @ W).tocsr()


def _tutte_solve(W, inner, fixed, U_fixed):
    """Tutte's method: the planar positions of ``inner`` with each at the ``W``-weighted mean
    of its neighbours, the vertices ``fixed`` held at ``U_fixed``."""
    Wi = W[inner]
    system = sp.identity(inner.size, format="csc") - Wi[:, inner].tocsc()
    return np.asarray(spla.spsolve(system, Wi[:, fixed] @ U_fixed)).reshape(-1, 2)


class FoldRepair:
    """Fold repair for embeddings of one surface mesh (caches its weights and adjacency).

    Parameters
    ----------
    V : (n, 3) float array, the surface (its angles give the Tutte weights)
    F : (m, 3) int array

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> P = V.copy()
    >>> i, j = F[0, 0], F[0, 1]
    >>> P[i] = 1.5 * V[j] - 0.5 * V[i]                # push vertex i past its neighbour j
    >>> P[i] /= np.linalg.norm(P[i])
    >>> repair = FoldRepair(V, F)
    >>> int(repair.bad_faces(P).sum())                # folded triangles
    2
    >>> repair(P)                                     # (rounds, vertices moved); P is repaired
    (0, 1)
    >>> int(repair.bad_faces(P).sum())
    0
    """

    def __init__(self, V, F):
        self.F = F
        self.W = mean_value_weights(V, F)
        A = (self.W != 0).astype(np.float64)
        self.A = ((A + A.T) > 0).astype(np.float64).tocsr()
        # faces around each vertex (CSR layout) and the vertex's corner in each
        order = np.argsort(F.ravel(), kind="stable")
        self._vf_ptr = np.concatenate([[0], np.cumsum(np.bincount(F.ravel(),
                                                                  minlength=V.shape[0]))])
        self._vf_face, self._vf_corner = order // 3, order % 3

    def _move_into_kernel(self, P, i):
        """Move vertex i to the Chebyshev centre of the kernel of its 1-ring (an LP).

        In the gnomonic chart at ``P[i]`` each incident triangle ``(i, j, k)`` is positive
        exactly when the vertex lies left of the line ``j -> k``: a half-plane. The point
        deepest inside all of them is found by maximising ``t`` subject to
        ``cross(u_k - u_j, x - u_j) >= t |u_k - u_j|``. Returns False if the kernel is empty.
        """
        from scipy.optimize import linprog

        s, e = self._vf_ptr[i], self._vf_ptr[i + 1]
        faces, corner = self._vf_face[s:e], self._vf_corner[s:e]
        j = self.F[faces, (corner + 1) % 3]
        k = self.F[faces, (corner + 2) % 3]
        c = P[i]
        e1 = np.cross(c, [1.0, 0.0, 0.0] if abs(c[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(c, e1)

        def chart(X):
            return np.stack([X @ e1, X @ e2], axis=1) / (X @ c)[:, None]

        if min((P[j] @ c).min(), (P[k] @ c).min()) <= 0.05:
            return False
        uj, uk = chart(P[j]), chart(P[k])
        scale = np.abs(np.concatenate([uj, uk])).max()
        if not (np.isfinite(scale) and scale > 0):
            return False
        uj, uk = uj / scale, uk / scale
        d = uk - uj
        nd = np.linalg.norm(d, axis=1)
        # cross(d, x - uj) = d0 x1 - d1 x0 - cross(d, uj) >= t |d|
        A_ub = np.stack([d[:, 1], -d[:, 0], nd], axis=1)
        b_ub = -(d[:, 0] * uj[:, 1] - d[:, 1] * uj[:, 0])
        if not (np.all(np.isfinite(A_ub)) and np.all(np.isfinite(b_ub))):
            return False
        res = linprog([0.0, 0.0, -1.0], A_ub=A_ub, b_ub=b_ub,
                      bounds=[(None, None), (None, None), (None, 1.0)], method="highs")
        if res.status != 0 or res.x[2] <= 0:
            return False
        x = res.x[:2] * scale
        X = c + x[0] * e1 + x[1] * e2
        P[i] = X / np.linalg.norm(X)
        return True

    def _kernel_sweeps(self, P, flatness, sweeps=3, max_vertices=2000):
        moved = set()
        for _ in range(sweeps):
            bad = self.bad_faces(P, flatness)
            if not bad.any():
                break
            verts = np.unique(self.F[bad].ravel())
            if verts.size > max_vertices:
                break
            for i in verts:
                fi = self._vf_face[self._vf_ptr[i]:self._vf_ptr[i + 1]]
                if not self.bad_faces_subset(P, fi, flatness).any():
                    continue                          # fixed by moving a neighbour already
                if self._move_into_kernel(P, int(i)):
                    moved.add(int(i))
        return moved

    def _tutte_in_chart(self, P, inside, boundary):
        c = P[inside].sum(axis=0)
        c /= np.linalg.norm(c)
        if (P[np.concatenate([inside, boundary])] @ c).min() <= 0.05:
            return False                             # the region is too large for one chart
        e1 = np.cross(c, [1.0, 0.0, 0.0] if abs(c[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(c, e1)
        Pb = P[boundary]
        ub = np.stack([Pb @ e1, Pb @ e2], axis=1) / (Pb @ c)[:, None]
        u = _tutte_solve(self.W, inside, boundary, ub)
        if not np.all(np.isfinite(u)):
            return False
        X = c + u[:, :1] * e1 + u[:, 1:] * e2
        P[inside] = X / np.linalg.norm(X, axis=1, keepdims=True)
        return True

    def bad_faces(self, P, flatness: float = 0.0) -> np.ndarray:
        """Faces folded or flatter than ``det[a, b, c] <= flatness * (longest edge)^2``.

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> V, F = icosphere(1)
        >>> repair = FoldRepair(V, F)
        >>> int(repair.bad_faces(V).sum()), int(repair.bad_faces(V[:, [1, 0, 2]]).sum())  # mirrored
        (0, 80)
        """
        det = orientation_determinants(P, self.F)
        if flatness <= 0:
            return det <= 0
        Q = P[self.F]
        l2 = np.max([((Q[:, i] - Q[:, (i + 1) % 3]) ** 2).sum(axis=1) for i in range(3)], axis=0)
        return det <= flatness * l2

    def bad_faces_subset(self, P, faces, flatness: float = 0.0) -> np.ndarray:
        """:meth:`bad_faces` restricted to the given faces.

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> V, F = icosphere(1)
        >>> repair = FoldRepair(V, F)
        >>> repair.bad_faces_subset(V[:, [1, 0, 2]], np.array([0, 5]))
        array([ True,  True])
        """
        Q = P[self.F[faces]]
        det = np.einsum("ij,ij->i", Q[:, 0], np.cross(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0]))
        if flatness <= 0:
            return det <= 0
        l2 = np.max([((Q[:, i] - Q[:, (i + 1) % 3]) ** 2).sum(axis=1) for i in range(3)], axis=0)
        return det <= flatness * l2

    def __call__(self, P, max_rounds: int = 30, flatness: float = 0.0):
        """Repair ``P`` in place: remove folded (and, optionally, nearly flat) triangles.

        Parameters
        ----------
        P : (n, 3) float array, unit vectors (modified)
        max_rounds : int
        flatness : float
            Also treat triangles with ``det <= flatness * (longest edge)^2`` as bad.

        Returns
        -------
        rounds : int
            Rounds used (``max_rounds + 1`` when folds remain).
        moved : int
            Number of vertices moved.
        """
        F, A = self.F, self.A
        n = P.shape[0]
        moved = np.zeros(n, dtype=bool)
        moved[list(self._kernel_sweeps(P, flatness))] = True
        for rnd in range(1, max_rounds + 1):
            bad = self.bad_faces(P, flatness)
            if not bad.any():
                return rnd - 1, int(moved.sum())
            mask = np.zeros(n, dtype=bool)
            mask[F[bad].ravel()] = True
            for _ in range(rnd + 1):
                mask |= (A @ mask.astype(np.float64)) > 0
            # fill holes: outside components other than the largest join the region
            out = np.flatnonzero(~mask)
            if out.size == 0:
                break
            ncomp, lab = connected_components(A[out][:, out], directed=False)
            if ncomp > 1:
                mask[out[lab != np.argmax(np.bincount(lab))]] = True
            ins = np.flatnonzero(mask)
            ncomp, lab = connected_components(A[ins][:, ins], directed=False)
            for k in range(ncomp):
                inside = ins[lab == k]
                ring = (np.asarray(A[inside].sum(axis=0)).ravel() > 0) & ~mask
                if self._tutte_in_chart(P, inside, np.flatnonzero(ring)):
                    moved[inside] = True
        if self.bad_faces(P, flatness).any():
            return max_rounds + 1, int(moved.sum())
        return max_rounds, int(moved.sum())


def _one_ring(F, v):
    """The neighbours of vertex ``v`` in cyclic order (counter-clockwise seen from outside)."""
    faces = F[(F == v).any(axis=1)]
    k = np.argmax(faces == v, axis=1)
    a = faces[np.arange(len(faces)), (k + 1) % 3]
    b = faces[np.arange(len(faces)), (k + 2) % 3]
    nxt = dict(zip(a.tolist(), b.tolist()))
    ring = [int(a[0])]
    while len(ring) < len(a):
        ring.append(nxt[ring[-1]])
    return np.array(ring)


def tutte_sphere(V, F, W=None, cap_degrees: float = 75.0) -> np.ndarray:
    """A fold-free spherical embedding by Tutte's method in a gnomonic chart.

    The vertex ``v0`` of largest valence goes to the north pole; its neighbours are placed, in
    order and spaced by edge length, on the circle of gnomonic radius ``tan(cap_degrees)``
    about the south pole, and every other vertex by Tutte's barycentric method with positive
    (mean-value) weights. The gnomonic projection maps great circles to straight lines, so each
    spherical triangle of the cap has the orientation of its planar image, which Tutte's theorem
    (Floater 2003, for a strictly convex boundary and positive weights) makes positive; the
    triangles around ``v0`` are positive because the ring turns once around the pole. This is
    the fallback when the conformal route cannot be repaired; its area distortion is large until
    the balancing stage evens it out.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, closed, genus 0, outward
    W : sparse (n, n), optional, row-normalised positive weights (mean-value by default)
    cap_degrees : float in (0, 90)

    Returns
    -------
    Vs : (n, 3) float array, unit vectors
    """
    n = V.shape[0]
    W = mean_value_weights(V, F) if W is None else W
    v0 = int(np.argmax(np.bincount(F.ravel(), minlength=n)))
    ring = _one_ring(F, v0)
    seg = np.linalg.norm(V[np.roll(ring, -1)] - V[ring], axis=1)
    theta = 2 * np.pi * np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / seg.sum()
    R = np.tan(np.radians(cap_degrees))
    U = np.zeros((n, 2))
    U[ring] = R * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    inner = np.setdiff1d(np.arange(n), np.concatenate([[v0], ring]))
    if inner.size:
        U[inner] = _tutte_solve(W, inner, ring, U[ring])
    for mirror in (1.0, -1.0):
        X = np.column_stack([U[:, 0], mirror * U[:, 1], -np.ones(n)])
        X[v0] = [0.0, 0.0, 1.0]
        X /= np.linalg.norm(X, axis=1, keepdims=True)
        if (orientation_determinants(X, F) > 0).sum() > F.shape[0] // 2:
            return X
    return X


#: smoothing steps of the face-normal indicator that splits a mesh into two halves
HALVES_SMOOTHING = 10


def _face_adjacency(F, h2e):
    """Faces sharing an edge, as a symmetric sparse matrix (every edge has two faces)."""
    face = np.repeat(np.arange(F.shape[0]), 3)
    order = np.argsort(h2e, kind="stable")
    a, b = face[order[0::2]], face[order[1::2]]
    m = F.shape[0]
    return sp.csr_matrix((np.ones(2 * a.size), (np.r_[a, b], np.r_[b, a])), shape=(m, m))


def _largest_part(G, mask, area):
    """The face-connected component of ``mask`` with the largest area."""
    idx = np.flatnonzero(mask)
    k, label = connected_components(G[idx][:, idx], directed=False)
    out = np.zeros_like(mask)
    out[idx[label == np.argmax(np.bincount(label, weights=area[idx], minlength=k))]] = True
    return out


def split_into_discs(V, F, max_rounds: int = 50):
    """Split a closed genus-0 mesh into two topological discs, a front and a back.

    The direction ``e`` in which the mesh is thinnest (the smallest principal axis of its
    area) defines the halves: faces whose normal, smoothed over ``HALVES_SMOOTHING`` rings,
    points along ``e`` form the front, the others the back. On a long thin part (a blade, a
    limb, a finger) that cut runs along its whole length, on both sides, so each half is a
    strip rather than a tube. The front is then made a disc: its largest connected part,
    with every part of the back not connected to the back's largest part added to it, and
    every vertex where the boundary touches itself (the halves meet at a corner only)
    given to the front, until the common boundary is one simple cycle.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, closed, genus 0, outward
    max_rounds : int
        Rounds of the repair of pinched boundary vertices.

    Returns
    -------
    front : (m,) bool array, the faces of the first disc (the others form the second)
    cycle : (k,) int array, the common boundary, in the order of the front's halfedges
        (counter-clockwise around the front seen from outside)

    Raises
    ------
    EmbeddingError
        No split into two discs was found.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> front, cycle = split_into_discs(V * [1.0, 3.0, 0.3], F)     # thinnest along z
    >>> bool(0.3 < front.mean() < 0.7), bool(abs(V[cycle, 2]).max() < 0.5)
    (True, True)
    """
    n = V.shape[0]
    area = face_areas(V, F)
    C = V[F].mean(axis=1)
    X = C - (area[:, None] * C).sum(axis=0) / area.sum()
    _, axes = np.linalg.eigh(np.einsum("f,fi,fj->ij", area, X, X))
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    h = N @ axes[:, 0]
    tail, head = halfedges(F)
    E, h2e, _ = unique_edges(F, n)
    G = _face_adjacency(F, h2e)
    mean = sp.diags(1.0 / np.asarray(G.sum(axis=1)).ravel()) @ G
    for _ in range(HALVES_SMOOTHING):
        h = 0.5 * (h + mean @ h)
    front = h > 0
    for _ in range(max_rounds):
        if front.all() or not front.any():
            break
        front = _largest_part(G, front, area)
        front = ~_largest_part(G, ~front, area)
        in_front = np.repeat(front, 3)
        n_front = np.bincount(h2e, weights=in_front, minlength=E.shape[0])
        boundary = in_front & (n_front[h2e] == 1)
        out = np.bincount(tail[boundary], minlength=n)
        pinched = np.flatnonzero(out > 1)
        if pinched.size == 0:
            nxt = np.full(n, -1)
            nxt[tail[boundary]] = head[boundary]
            cycle = [int(tail[boundary][0])]
            for _ in range(int(boundary.sum())):
                v = int(nxt[cycle[-1]])
                if v == cycle[0]:
                    break
                cycle.append(v)
            if len(cycle) == int(boundary.sum()) >= 3:     # one simple cycle
                return front, np.array(cycle)
            break
        front = front | np.isin(F, pinched).any(axis=1)
    raise EmbeddingError("could not split the mesh into two discs along its thinnest direction")


def tutte_halves(V, F, W=None) -> np.ndarray:
    """A spherical embedding from Tutte maps of two halves of the mesh onto two hemispheres.

    The mesh is split into two discs with a common boundary (:func:`split_into_discs`); the
    boundary goes to the equator, spaced by edge length, each disc to the unit disc by
    Tutte's method with mean-value weights (fold-free in the plane: Floater 2003) and on to
    its hemisphere by stereographic projection. Unlike :func:`tutte_sphere`, whose boundary
    is one vertex's ring, this leaves no long tube in either disc: a blade, a limb or a
    finger is cut along its length, and a map that telescopes a tube into a point
    (exponentially, beyond what float64 resolves) is avoided. Stereographic projection is
    conformal but does not map straight edges to great circles, so a few large triangles can
    fold; :class:`FoldRepair` removes them.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, closed, genus 0, outward
    W : sparse (n, n), optional, row-normalised positive weights (mean-value by default)

    Returns
    -------
    Vs : (n, 3) float array, unit vectors (the front on the southern hemisphere)

    Raises
    ------
    EmbeddingError
        No split into two discs was found.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere, orientation_determinants
    >>> V, F = icosphere(3)
    >>> Y = V * [1.0, 4.0, 0.2]
    >>> X = tutte_halves(Y, F)
    >>> _ = FoldRepair(Y, F)(X)                    # the folds of large triangles, if any
    >>> int((orientation_determinants(X, F) <= 0).sum()), bool(np.allclose((X * X).sum(1), 1))
    (0, True)
    """
    n = V.shape[0]
    W = mean_value_weights(V, F) if W is None else W
    front, cycle = split_into_discs(V, F)
    seg = np.linalg.norm(V[np.roll(cycle, -1)] - V[cycle], axis=1)
    theta = 2 * np.pi * np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / seg.sum()
    U = np.zeros((n, 2))
    U[cycle] = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    X = np.zeros((n, 3))
    on_cycle = np.zeros(n, dtype=bool)
    on_cycle[cycle] = True
    for half, z in ((front, -1.0), (~front, 1.0)):
        inside = np.zeros(n, dtype=bool)
        inside[F[half].ravel()] = True
        inner = np.flatnonzero(inside & ~on_cycle)
        if inner.size:
            U[inner] = _tutte_solve(W, inner, cycle, U[cycle])
        r2 = (U[inner] ** 2).sum(axis=1)
        X[inner] = np.column_stack([2 * U[inner], z * (1 - r2)]) / (1 + r2)[:, None]
    X[cycle, :2] = U[cycle]
    if (orientation_determinants(X, F) > 0).sum() < F.shape[0] // 2:
        X[:, 1] *= -1
    return X
