"""Per-face and per-vertex quantities and the cotangent finite-element operators.

Conventions (DESIGN.md): the Laplace-Beltrami operator is negative semi-definite, so the
cotangent matrix ``L`` has non-positive diagonal and ``-L`` is positive semi-definite; the weak
form of ``Delta f = g`` is ``L f = M g``. Eigenvalues are reported positive:
``-L phi = lambda M phi``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .._validation import check_choice
from ._arrays import as_mesh, unique_edges

__all__ = [
    "face_areas",
    "face_normals",
    "face_angles",
    "vertex_normals",
    "corner_normals",
    "normal_turn",
    "cotan_laplacian",
    "mass_matrix",
    "surface_area",
    "signed_volume",
]


def _edge_vectors(V, F):
    # e[:, k] runs from corner k+1 to corner k+2 (the edge opposite corner k)
    P = V[F]
    return np.stack([P[:, 2] - P[:, 1], P[:, 0] - P[:, 2], P[:, 1] - P[:, 0]], axis=1)


def _double_area_vectors(V, F):
    P = V[F]
    return np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])


def face_areas(V, F) -> np.ndarray:
    """Area of every triangle, ``|(b - a) x (c - a)| / 2``.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    A : (m,) float array

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> round(float(face_areas(V, F).sum()), 3)
    12.506
    """
    V, F = as_mesh(V, F)
    return 0.5 * np.linalg.norm(_double_area_vectors(V, F), axis=1)


def surface_area(V, F) -> float:
    """Total area of the mesh (sum of :func:`face_areas`).

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> round(surface_area(*icosphere(4)), 3)          # 4 pi = 12.566, approached from below
    12.551
    """
    return float(face_areas(V, F).sum())


def signed_volume(V, F) -> float:
    """Enclosed volume ``sum_f det[a, b, c] / 6``; positive for a closed outward-oriented mesh.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(4)
    >>> round(signed_volume(V, F), 2)   # 4 pi / 3 = 4.19
    4.18
    """
    V, F = as_mesh(V, F)
    P = V[F]
    return float(np.einsum("ij,ij->i", P[:, 0], np.cross(P[:, 1], P[:, 2])).sum() / 6.0)


def face_normals(V, F) -> np.ndarray:
    """Unit normal of every triangle, ``(b - a) x (c - a)`` normalised (zero for zero area).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, counter-clockwise seen from outside

    Returns
    -------
    N : (m, 3) float array, unit vectors (outward for an outward-oriented mesh)

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(1)
    >>> N = face_normals(V, F)
    >>> bool(((N * V[F].mean(axis=1)).sum(axis=1) > 0).all())
    True
    """
    V, F = as_mesh(V, F)
    N = _double_area_vectors(V, F)
    norm = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, norm, out=np.zeros_like(N), where=norm > 0)


def face_angles(V, F) -> np.ndarray:
    """Interior angle at every corner, ``alpha[f, k]`` at vertex ``F[f, k]`` (radians).

    Computed as ``atan2(|u x v|, u . v)``, which is accurate for needle-thin triangles.

    Returns
    -------
    alpha : (m, 3) float array

    Examples
    --------
    >>> V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    >>> np.degrees(face_angles(V, np.array([[0, 1, 2]]))).round(6)
    array([[90., 45., 45.]])
    """
    V, F = as_mesh(V, F)
    P = V[F]
    alpha = np.empty(F.shape, dtype=np.float64)
    for k in range(3):
        u = P[:, (k + 1) % 3] - P[:, k]
        v = P[:, (k + 2) % 3] - P[:, k]
        alpha[:, k] = np.arctan2(np.linalg.norm(np.cross(u, v), axis=1),
                                 np.einsum("ij,ij->i", u, v))
    return alpha


def vertex_normals(V, F, weighting: str = "angle") -> np.ndarray:
    """Unit vertex normals: face normals averaged with angle or area weights.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    weighting : {"angle", "area"}
        ``"angle"`` weights each face normal by the corner angle at the vertex (Thürmer &
        Wüthrich 1998), which does not depend on how a region is triangulated; ``"area"``
        weights by face area.

    Returns
    -------
    N : (n, 3) float array, unit vectors (zero for unreferenced vertices)

    References
    ----------
    G. Thürmer and C. A. Wüthrich, "Computing vertex normals from polygonal facets",
    Journal of Graphics Tools 3(1), 1998.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> float(abs(vertex_normals(V, F) - V).max()) < 0.01
    True
    """
    check_choice(weighting, "weighting", ("angle", "area"))
    V, F = as_mesh(V, F)
    Nf = face_normals(V, F)
    if weighting == "angle":
        W = face_angles(V, F)
    else:
        W = np.repeat(face_areas(V, F)[:, None], 3, axis=1)
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], W[:, k, None] * Nf)
    norm = np.linalg.norm(N, axis=1, keepdims=True)
    return np.divide(N, norm, out=np.zeros_like(N), where=norm > 0)


def normal_turn(V, F) -> float:
    """How far a mesh's (angle-weighted) vertex normals turn across its edges: the median
    over the edges of the angle between the normals at the two ends, in degrees. About the
    curvature times the edge length where the mesh samples a smooth surface; a fine mesh's
    normals turn by a few degrees per edge, ripples a few edges wide by tens.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> [round(normal_turn(*icosphere(level)), 1) for level in (2, 4)]   # the edges' arcs
    [17.3, 4.3]
    """
    V, F = as_mesh(V, F)
    N = vertex_normals(V, F)
    E = unique_edges(F, len(V))[0]
    cos = np.clip(np.einsum("ij,ij->i", N[E[:, 0]], N[E[:, 1]]), -1.0, 1.0)
    return float(np.degrees(np.median(np.arccos(cos))))


def corner_normals(V, F, crease_angle: float | None = None,
                   weighting: str = "angle") -> np.ndarray:
    """Unit normals at every face corner, averaged round each vertex without crossing creases.

    The normal at corner ``k`` of face ``f`` is the weighted mean (as
    :func:`vertex_normals`) of the normals of the faces round vertex ``F[f, k]`` that turn
    by at most ``crease_angle`` degrees from face ``f``'s own normal. Across an edge sharper
    than that, the two sides keep their own normals, so that a surface following the
    interpolated corner normals may keep the edge sharp instead of rounding it over a
    triangle's width. Round a vertex with no such edge every corner has the vertex normal.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    crease_angle : float in (0, 180], optional
        In degrees; ``None`` (or 180) averages over all faces round the vertex, so that
        ``corner_normals(V, F)`` is ``vertex_normals(V, F)[F]``.
    weighting : {"angle", "area"}

    Returns
    -------
    N : (m, 3, 3) float array, ``N[f, k]`` the unit normal at corner ``k`` of face ``f``
        (the vertex normal where a degenerate face leaves nothing to average)

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> bool(np.allclose(corner_normals(V, F), vertex_normals(V, F)[F]))
    True
    >>> T = np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
    >>> G = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])    # a tetrahedron
    >>> bool(np.allclose(corner_normals(T, G, 60.0), face_normals(T, G)[:, None]))
    True
    """
    check_choice(weighting, "weighting", ("angle", "area"))
    V, F = as_mesh(V, F)
    N_vertex = vertex_normals(V, F, weighting)
    if crease_angle is None:
        return N_vertex[F]
    crease_angle = float(crease_angle)
    if not 0.0 < crease_angle <= 180.0:
        raise ValueError(f"crease_angle must be in (0, 180] degrees, got {crease_angle!r}")
    Nf = face_normals(V, F)
    W = face_angles(V, F) if weighting == "angle" else np.repeat(
        face_areas(V, F)[:, None], 3, axis=1)
    # corners grouped by vertex; every pair of corners at one vertex (valence^2 pairs)
    order = np.argsort(F.ravel(), kind="stable")
    vert = F.ravel()[order]
    face = order // 3
    start = np.flatnonzero(np.r_[True, vert[1:] != vert[:-1]])
    size = np.diff(np.r_[start, len(vert)])
    group = np.repeat(np.arange(len(start)), size)
    a = np.repeat(np.arange(len(vert)), size[group])
    first = np.repeat(np.cumsum(size[group]) - size[group], size[group])
    b = start[group[a]] + np.arange(len(a)) - first
    cos = np.einsum("ij,ij->i", Nf[face[a]], Nf[face[b]])
    keep = cos >= np.cos(np.radians(crease_angle)) - 1e-12
    a, b = a[keep], b[keep]
    acc = np.zeros((len(vert), 3))
    np.add.at(acc, a, W.ravel()[order][b, None] * Nf[face[b]])
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    acc = np.where(norm > 0, acc / np.where(norm > 0, norm, 1.0), N_vertex[vert])
    N = np.empty((F.size, 3))
    N[order] = acc
    return N.reshape(F.shape[0], 3, 3)


def _cotangents(V, F):
    """Cotangent of every corner angle (zero on zero-area faces) and the face areas."""
    E = _edge_vectors(V, F)
    dbl = np.linalg.norm(_double_area_vectors(V, F), axis=1)
    C = np.empty(F.shape, dtype=np.float64)
    for k in range(3):
        # the angle at corner k lies between the two edges that do not face it
        C[:, k] = -np.einsum("ij,ij->i", E[:, (k + 1) % 3], E[:, (k + 2) % 3])
    np.divide(C, dbl[:, None], out=C, where=dbl[:, None] > 0)
    C[dbl == 0] = 0.0
    return C, 0.5 * dbl


def cotan_laplacian(V, F) -> sp.csr_matrix:
    """Cotangent Laplacian (stiffness matrix), negative semi-definite.

    ``L_ij = (cot alpha_ij + cot beta_ij) / 2`` for each edge ``ij`` with opposite angles
    ``alpha_ij, beta_ij``, and ``L_ii = -sum_j L_ij``; it is the Galerkin matrix
    ``L_ij = -int grad phi_i . grad phi_j`` of piecewise-linear hat functions, so that
    ``x^T L x = -int |grad x|^2 <= 0``. Zero-area faces contribute nothing.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array

    Returns
    -------
    L : (n, n) scipy.sparse.csr_matrix, symmetric, ``L @ 1 = 0``

    References
    ----------
    U. Pinkall and K. Polthier, "Computing discrete minimal surfaces and their conjugates",
    Experimental Mathematics 2(1), 1993.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> L = cotan_laplacian(V, F)
    >>> float(abs(L @ np.ones(len(V))).max()) < 1e-12
    True
    """
    V, F = as_mesh(V, F)
    n = V.shape[0]
    C, _ = _cotangents(V, F)
    # corner k faces the edge (k+1, k+2)
    i = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    j = np.concatenate([F[:, 2], F[:, 0], F[:, 1]])
    w = 0.5 * np.concatenate([C[:, 0], C[:, 1], C[:, 2]])
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([j, i, i, j])
    vals = np.concatenate([w, w, -w, -w])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def _voronoi_areas(V, F):
    """Mixed Voronoi area of each corner (Meyer et al. 2003), (m, 3)."""
    C, A = _cotangents(V, F)
    E = _edge_vectors(V, F)
    sq = np.einsum("ijk,ijk->ij", E, E)          # squared length of the edge facing corner k
    W = np.empty(F.shape, dtype=np.float64)
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        # the Voronoi region of corner k is bounded by the edges k->k1 (facing k2) and k->k2
        W[:, k] = (sq[:, k2] * C[:, k2] + sq[:, k1] * C[:, k1]) / 8.0
    obtuse = C < 0                                 # cot < 0  <=>  angle > 90 degrees
    any_obtuse = obtuse.any(axis=1)
    W[any_obtuse] = np.where(obtuse[any_obtuse], 0.5, 0.25) * A[any_obtuse, None]
    return W


def mass_matrix(V, F, kind: str = "barycentric") -> sp.csr_matrix:
    """Finite-element mass matrix of piecewise-linear functions.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    kind : {"barycentric", "voronoi", "full"}
        ``"barycentric"``: diagonal, a third of each incident face area per vertex.
        ``"voronoi"``: diagonal, mixed Voronoi areas (Meyer et al. 2003: the circumcentric
        Voronoi cell of a non-obtuse triangle, otherwise half the area to the obtuse corner and a
        quarter to the others). ``"full"``: the consistent Galerkin matrix
        ``M_ij = int phi_i phi_j``, per face ``A (1 + delta_ij) / 12``.

    Returns
    -------
    M : (n, n) scipy.sparse.csr_matrix, symmetric positive semi-definite, ``1^T M 1`` = area

    References
    ----------
    M. Meyer, M. Desbrun, P. Schröder and A. H. Barr, "Discrete differential-geometry operators
    for triangulated 2-manifolds", Visualization and Mathematics III, 2003.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> round(float(mass_matrix(V, F, "full").sum()), 3)
    12.506
    """
    check_choice(kind, "kind", ("barycentric", "voronoi", "full"))
    V, F = as_mesh(V, F)
    n = V.shape[0]
    if kind == "full":
        A = face_areas(V, F)
        rows = np.repeat(F, 3, axis=1).reshape(-1)
        cols = np.tile(F, (1, 3)).reshape(-1)
        vals = (A[:, None] / 12.0 * (1.0 + np.eye(3).reshape(1, 9))).reshape(-1)
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    if kind == "barycentric":
        W = np.repeat(face_areas(V, F)[:, None] / 3.0, 3, axis=1)
    else:
        W = _voronoi_areas(V, F)
    d = np.bincount(F.reshape(-1), weights=W.reshape(-1), minlength=n)
    return sp.diags(d).tocsr()
