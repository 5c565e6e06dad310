"""Topological and geometric checks for closed genus-0 triangle meshes.

:func:`check` runs the checks in a fixed order, from the most basic (a face repeating a vertex)
to the global ones (genus, orientation), and raises the first failure as a specific
:class:`~sns_np.mesh.errors.MeshDefectError` subclass carrying a count and an example, so that a
bad mesh is rejected before any solver sees it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ._arrays import as_mesh, halfedges, unique_edges
from .errors import (
    BoundaryError,
    DegenerateFaceError,
    DisconnectedError,
    DuplicateFaceError,
    GenusError,
    NonManifoldError,
    OrientationError,
    UnreferencedVertexError,
)
from .operators import face_areas, signed_volume

__all__ = ["MeshSummary", "check", "DEGENERATE_TOL"]

#: a face is degenerate when ``2 * area <= DEGENERATE_TOL * (longest edge)^2``, i.e. when the
#: sine of its largest angle is numerically zero (a 0.12 degree sliver has 2e-3)
DEGENERATE_TOL = 1e-12


@dataclass(frozen=True)
class MeshSummary:
    """What :func:`check` measured on a valid mesh.

    Examples
    --------
    >>> from sns_np.mesh import check, icosphere
    >>> s = check(*icosphere(2))
    >>> s.n_vertices, s.n_edges, s.n_faces, s.euler_characteristic
    (162, 480, 320, 2)
    >>> round(s.area, 3), round(s.volume, 3)               # 4 pi, 4 pi / 3 from below
    (12.33, 4.047)
    """

    n_vertices: int
    n_edges: int
    n_faces: int
    euler_characteristic: int
    area: float
    volume: float
    min_face_area: float


def _fmt_edge(E, e):
    return f"({int(E[e, 0])}, {int(E[e, 1])})"


def _check_faces(V, F):
    n = V.shape[0]
    rep = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if rep.any():
        f = int(np.flatnonzero(rep)[0])
        raise DegenerateFaceError(
            f"{int(rep.sum())} face(s) repeat a vertex index, e.g. face {f} = {F[f].tolist()}; "
            "expected three distinct vertices per triangle", count=int(rep.sum()), example=f)
    S = np.sort(F, axis=1)
    order = np.lexsort((S[:, 2], S[:, 1], S[:, 0]))
    dup = np.flatnonzero((S[order][1:] == S[order][:-1]).all(axis=1))
    if dup.size:
        f, g = sorted((int(order[dup[0]]), int(order[dup[0] + 1])))
        raise DuplicateFaceError(
            f"{dup.size} duplicate face(s): e.g. faces {f} and {g} both use vertices "
            f"{sorted(F[f].tolist())}; expected every triangle once", count=int(dup.size),
            example=(f, g))
    used = np.zeros(n, dtype=bool)
    used[F.reshape(-1)] = True
    if not used.all():
        free = np.flatnonzero(~used)
        raise UnreferencedVertexError(
            f"{free.size} of {n} vertices are used by no face, e.g. vertex {int(free[0])}; "
            "remove them (sns_np.mesh.load does) so that every vertex belongs to the surface",
            count=int(free.size), example=int(free[0]))


def _check_edges(F, n):
    E, h2e, count = unique_edges(F, n)
    over = np.flatnonzero(count > 2)
    if over.size:
        e = int(over[0])
        raise NonManifoldError(
            f"{over.size} non-manifold edge(s) shared by more than two faces, e.g. edge "
            f"{_fmt_edge(E, e)} in {int(count[e])} faces", count=int(over.size),
            example=tuple(int(i) for i in E[e]))
    open_ = np.flatnonzero(count == 1)
    if open_.size:
        e = int(open_[0])
        raise BoundaryError(
            f"the mesh is open: {open_.size} boundary edge(s) belong to a single face, e.g. "
            f"edge {_fmt_edge(E, e)}; expected a closed surface", count=int(open_.size),
            example=tuple(int(i) for i in E[e]))
    tail, head = halfedges(F)
    key = tail * np.int64(n) + head
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order][1:] == key[order][:-1])
    if same.size:
        h = int(order[same[0] + 1])
        raise OrientationError(
            f"inconsistent winding: {same.size} edge(s) are traversed in the same direction by "
            f"both of their faces, e.g. edge ({int(tail[h])}, {int(head[h])}) in faces "
            f"{int(order[same[0]]) // 3} and {h // 3}; expected each edge once in each direction",
            count=int(same.size), example=h // 3)
    return E, h2e


def _check_vertex_fans(F, n, h2e):
    """Every vertex's corners must form one fan: link corners across shared edges."""
    m = F.shape[0]
    tail, head = halfedges(F)
    order = np.argsort(h2e, kind="stable")      # the two halfedges of each edge are adjacent
    h1, h2 = order[0::2], order[1::2]
    corner = np.arange(3 * m).reshape(m, 3)

    def corner_at(h, v):
        f = h // 3
        k = np.argmax(F[f] == v[:, None], axis=1)
        return corner[f, k]

    a = np.concatenate([corner_at(h1, tail[h1]), corner_at(h1, head[h1])])
    b = np.concatenate([corner_at(h2, tail[h1]), corner_at(h2, head[h1])])
    G = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(3 * m, 3 * m))
    _, label = connected_components(G, directed=False)
    pairs = np.unique(F.reshape(-1) * np.int64(3 * m) + label)
    fans = np.bincount(pairs // (3 * m), minlength=n)
    bad = np.flatnonzero(fans > 1)
    if bad.size:
        v = int(bad[0])
        raise NonManifoldError(
            f"{bad.size} non-manifold (pinched) vertex/vertices whose faces form several "
            f"separate fans, e.g. vertex {v} with {int(fans[v])} fans; expected one disc "
            "around every vertex", count=int(bad.size), example=v)


def check(V, F, *, degenerate_tol: float = DEGENERATE_TOL) -> MeshSummary:
    """Check that ``(V, F)`` is a closed, oriented, genus-0 manifold triangle mesh.

    The checks, in order (the first failure is raised):

    1. no face repeats a vertex (:class:`DegenerateFaceError`);
    2. no two faces share the same three vertices (:class:`DuplicateFaceError`);
    3. every vertex is used by a face (:class:`UnreferencedVertexError`; :func:`load` removes
       such vertices, ``check`` treats them as an error since they have no place on the sphere);
    4. every edge has at most two faces (:class:`NonManifoldError`) and at least two
       (:class:`BoundaryError`);
    5. the two faces of every edge traverse it in opposite directions (:class:`OrientationError`);
    6. the faces around every vertex form a single fan (:class:`NonManifoldError`);
    7. one connected component (:class:`DisconnectedError`);
    8. Euler characteristic ``V - E + F = 2``, i.e. genus 0 (:class:`GenusError`);
    9. no face of (numerically) zero area: ``2 A > degenerate_tol * (longest edge)^2``
       (:class:`DegenerateFaceError`);
    10. outward orientation, signed volume > 0 (:class:`OrientationError`).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    degenerate_tol : float
        Threshold on ``2 A / l_max^2`` (about the sine of the largest angle) below which a face
        counts as zero-area.

    Returns
    -------
    MeshSummary
        Counts, Euler characteristic, area, volume and smallest face area.

    Raises
    ------
    MeshDefectError
        The specific subclass for the first defect found, with ``count`` and ``example``.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> check(V, F).euler_characteristic
    2
    >>> check(V, F[:, ::-1])                        # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    sns_np.mesh.errors.OrientationError: the mesh faces inwards: signed volume -4.0... < 0; ...
    """
    V, F = as_mesh(V, F)
    n, m = V.shape[0], F.shape[0]
    _check_faces(V, F)
    E, h2e = _check_edges(F, n)
    _check_vertex_fans(F, n, h2e)
    A = sp.coo_matrix((np.ones(E.shape[0]), (E[:, 0], E[:, 1])), shape=(n, n))
    ncomp, label = connected_components(A, directed=False)
    if ncomp > 1:
        sizes = np.bincount(label)
        raise DisconnectedError(
            f"the mesh has {ncomp} connected components (vertex counts "
            f"{sorted(sizes.tolist(), reverse=True)[:5]}{'...' if ncomp > 5 else ''}); "
            "expected one", count=int(ncomp), example=int(np.flatnonzero(label != label[0])[0]))
    chi = n - E.shape[0] + m
    if chi != 2:
        genus = (2 - chi) / 2
        g = int(genus) if genus == int(genus) else genus
        raise GenusError(
            f"Euler characteristic V - E + F = {n} - {E.shape[0]} + {m} = {chi}, i.e. genus {g}; "
            "expected 2 (genus 0, a topological sphere)", count=g)
    area = face_areas(V, F)
    P = V[F]
    lmax2 = np.max(np.stack([np.sum((P[:, 1] - P[:, 0]) ** 2, axis=1),
                             np.sum((P[:, 2] - P[:, 1]) ** 2, axis=1),
                             np.sum((P[:, 0] - P[:, 2]) ** 2, axis=1)]), axis=0)
    flat = 2.0 * area <= degenerate_tol * lmax2
    if flat.any():
        f = int(np.flatnonzero(flat)[0])
        raise DegenerateFaceError(
            f"{int(flat.sum())} face(s) have (numerically) zero area, e.g. face {f} = "
            f"{F[f].tolist()} with area {area[f]:.3g}; expected non-degenerate triangles",
            count=int(flat.sum()), example=f)
    vol = signed_volume(V, F)
    if not vol > 0:
        raise OrientationError(
            f"the mesh faces inwards: signed volume {vol:.6g} < 0; expected outward "
            "(counter-clockwise seen from outside) faces; reverse them with F[:, ::-1]",
            count=m, example=0)
    return MeshSummary(n_vertices=n, n_edges=int(E.shape[0]), n_faces=m,
                       euler_characteristic=int(chi), area=float(area.sum()), volume=vol,
                       min_face_area=float(area.min()))
