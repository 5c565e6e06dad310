"""A surface over a mesh whose normals follow the mesh's interpolated vertex normals.

A fit to a mesh needs position targets between the vertices, and the flat triangles are the
wrong ones: a network that reproduces them reproduces their chordal error as curvature along
every edge. The Phong tessellation bends each triangle towards the vertex normals, one
triangle at a time. :class:`NormalHeights` asks the question for the whole mesh at once:
which surface ``q + h n`` (``q`` on the flat triangles, ``n`` the interpolated unit vertex
normal, ``h`` a height) has normals closest to ``n`` in least squares?

To first order in ``h``, the normal of ``q + h n`` over a flat face with unit normal ``nf``
is ``n`` where ``grad h = -t``, with ``t = n - (n . nf) nf`` the part of ``n`` along the face.
The field ``-t`` is not a gradient (``n`` is not the normal field of any surface), so ``h`` is
its least-squares potential, piecewise linear on the mesh's midpoint subdivision (``levels``
rounds, each splitting every triangle in four), tied to the mesh at its own vertices, the
only points a mesh knows exactly::

    (K + eps P) h = -G' A t,    eps = tie * mean diag(K)

``K = G' A G`` the stiffness matrix (minus :func:`~sns_np.mesh.cotan_laplacian`), ``G`` the
piecewise-linear gradient, ``A`` the faces' areas, ``P`` the diagonal matrix with 1 at the
mesh's vertices (the subdivision's first) and 0 at the midpoints. A large tie interpolates
the vertices and bends between them like Phong's tessellation, but for the mesh as a whole;
a small one follows the normals more closely and lets the surface leave the vertices where
the normals disagree with them (noise, sharp features). On a level-4 mesh of an ellipsoid,
the surface at the default tie (3e-2) is 6 times nearer the ellipsoid than the triangles
(1.2e-4 against 7.3e-4 of the semi-axes' scale) and its normals 17 times nearer
(0.066 against 1.13 degrees); docs/fitting.md ("The mesh's normals as a target") measures
it on every shared mesh and as a fit's target.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .._validation import as_points
from ._arrays import as_mesh
from .operators import cotan_laplacian, face_normals, vertex_normals

__all__ = ["midpoint_subdivision", "subdivided_points", "NormalHeights"]


def midpoint_subdivision(V, F, levels: int = 1):
    """Split every triangle into four at its edges' midpoints, ``levels`` times.

    Parameters
    ----------
    V : (n, d) float array, per-vertex data (positions, optionally with more columns, e.g.
        normals, which are averaged along each edge like the positions)
    F : (m, 3) int array
    levels : int >= 0

    Returns
    -------
    V2 : (n + e1 + e2 + ..., d) float array, the original vertices first, then each round's
        edge midpoints
    F2 : (4**levels * m, 3) int array. After one round, face ``f + k m`` is the child of face
        ``f`` at its corner ``k`` (``k`` = 0, 1, 2: the corner and the midpoints of its two
        edges) or, for ``k`` = 3, its middle triangle (the three midpoints), all oriented as
        ``f``; :func:`subdivided_points` follows points down the same numbering.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(1)
    >>> V2, F2 = midpoint_subdivision(V, F, 2)
    >>> len(V), len(V2), len(F2) == 16 * len(F)
    (42, 642, True)
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if V.ndim != 2 or F.ndim != 2 or F.shape[1] != 3:
        raise ValueError(f"V must be (n, d) and F (m, 3); got {V.shape} and {F.shape}")
    if int(levels) != levels or levels < 0:
        raise ValueError(f"levels must be an integer >= 0, got {levels!r}")
    for _ in range(int(levels)):
        n, m = len(V), len(F)
        # the edges ab, bc, ca of every face, each keyed by its sorted ends
        a, b = np.concatenate([F[:, 0], F[:, 1], F[:, 2]]), np.concatenate(
            [F[:, 1], F[:, 2], F[:, 0]])
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        key, first, edge = np.unique(lo * n + hi, return_index=True, return_inverse=True)
        V = np.vstack([V, 0.5 * (V[lo[first]] + V[hi[first]])])
        ab, bc, ca = (n + edge.reshape(3, m))
        x, y, z = F.T
        F = np.concatenate([np.c_[x, ab, ca], np.c_[ab, y, bc], np.c_[ca, bc, z],
                            np.c_[ab, bc, ca]])
    return V, F


def subdivided_points(face, beta, n_faces: int, levels: int):
    """Barycentric points ``(face, beta)`` of a mesh with ``n_faces`` faces, as points of its
    :func:`midpoint_subdivision` (``levels`` rounds): ``(face2, beta2)``, the same points.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(1)
    >>> V2, F2 = midpoint_subdivision(V, F, 3)
    >>> face, beta = np.array([0, 7, 79]), np.array([[0.2, 0.3, 0.5], [0.9, 0.05, 0.05],
    ...                                              [1 / 3, 1 / 3, 1 / 3]])
    >>> f2, b2 = subdivided_points(face, beta, len(F), 3)
    >>> x = np.einsum("kc,kci->ki", beta, V[F[face]])
    >>> bool(np.allclose(np.einsum("kc,kci->ki", b2, V2[F2[f2]]), x)), bool((b2 >= 0).all())
    (True, True)
    """
    face = np.array(face, dtype=np.int64)
    b = np.array(beta, dtype=np.float64)
    m = int(n_faces)
    for _ in range(int(levels)):
        # which child holds the point: the corner whose weight is at least a half, else the
        # middle triangle; and its weights there (the corner's child spans the corner and
        # its two edges' midpoints)
        k = np.full(len(face), 3)
        for c in (2, 1, 0):
            k[b[:, c] >= 0.5] = c
        nb = 2.0 * b
        for c in (0, 1, 2):
            s = k == c
            nb[s, c] -= 1.0
        s = k == 3
        nb[s] = 1.0 - 2.0 * b[s][:, [2, 0, 1]]
        face, b, m = face + k * m, nb, 4 * m
    np.clip(b, 0.0, 1.0, out=b)
    b /= b.sum(axis=1, keepdims=True)
    return face, b


class NormalHeights:
    """The heights ``h`` of the surface ``q + h n`` over a mesh whose normals follow its
    interpolated vertex normals ``n`` (module docstring).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array
    N : (n, 3) float array, optional
        Unit vertex normals (default: angle-weighted, :func:`~sns_np.mesh.vertex_normals`);
        pass the ones the heights are applied along.
    levels : int >= 0
        Rounds of midpoint subdivision of the piecewise-linear heights (0: one height per
        vertex). Each round has four times the unknowns; the solve is a sparse LU
        factorisation (SuperLU), about 4 s at 190,000 unknowns.
    tie : float >= 0
        How strongly the surface is held at the mesh's vertices, relative to the stiffness
        (module docstring); 3e-2 is the fit's choice (``NORMAL_HEIGHT_TIE``).

    Attributes
    ----------
    h : (n2,) heights at the subdivision's vertices (mesh units)
    F2 : (4**levels m, 3) the subdivision's faces
    seconds : float, the time the solve took

    Examples
    --------
    >>> from sns_np.mesh import face_normals, icosphere
    >>> V, F = icosphere(2)                       # the unit sphere's, 162 vertices
    >>> def angle(V, F):                          # mean angle (deg) to the sphere's normals
    ...     c = V[F].mean(axis=1)
    ...     c /= np.linalg.norm(c, axis=1, keepdims=True)
    ...     cos = np.einsum("ij,ij->i", face_normals(V, F), c)
    ...     return round(float(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean()), 2)
    >>> angle(*midpoint_subdivision(V, F, 2)), angle(*NormalHeights(V, F, levels=2).mesh())
    (4.54, 0.26)
    """

    def __init__(self, V, F, N=None, *, levels: int = 2, tie: float = 3e-2):
        V, F = as_mesh(V, F)
        N = vertex_normals(V, F, weighting="angle") if N is None else as_points(N, "N")
        if N.shape != V.shape:
            raise ValueError(f"N must have the shape of V {V.shape}, got {N.shape}")
        if int(levels) != levels or not 0 <= levels <= 6:
            raise ValueError(f"levels must be an integer in [0, 6], got {levels!r}")
        if not (np.isfinite(tie) and tie >= 0):
            raise ValueError(f"tie must be a finite number >= 0, got {tie!r}")
        t0 = time.perf_counter()
        self.levels, self.tie, self.n_faces = int(levels), float(tie), len(F)
        VN, F2 = midpoint_subdivision(np.hstack([V, N]), F, self.levels)
        V2, N2 = VN[:, :3], VN[:, 3:]
        # the face-wise part of the normal along each face, at its centre
        nf = face_normals(V2, F2)
        nc = N2[F2].sum(axis=1)
        nc /= np.linalg.norm(nc, axis=1, keepdims=True)
        t = nc - np.einsum("ij,ij->i", nc, nf)[:, None] * nf
        # -G'A t: corner i of a face gets A grad(phi_i) . t = (nf x e_i) . t / 2, e_i the
        # edge opposite it (from corner i+1 to i+2)
        rhs = np.zeros(len(V2))
        for i in range(3):
            e = V2[F2[:, (i + 2) % 3]] - V2[F2[:, (i + 1) % 3]]
            rhs -= 0.5 * np.bincount(F2[:, i], np.einsum("ij,ij->i", np.cross(nf, e), t),
                                     minlength=len(V2))
        K = -cotan_laplacian(V2, F2)
        # a tie of 0 leaves the mean of h free (K is singular): the smallest tie fixes it
        pin = np.zeros(len(V2))
        pin[:len(V)] = max(self.tie, 1e-12) * K.diagonal().mean()
        self.h = splu((K + sp.diags(pin)).tocsc()).solve(rhs)
        self.F2, self._mesh = F2, (V, F, N)          # the mesh itself, for mesh()
        self.seconds = time.perf_counter() - t0

    def mesh(self):
        """The surface itself as a mesh: the subdivision's vertices moved along their unit
        (interpolated) normals by ``h``, ``(V2, F2)``.

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> V, F = icosphere(1)
        >>> V2, F2 = NormalHeights(V, F, levels=1, tie=1.0).mesh()   # held at the vertices
        >>> V2.shape, F2.shape
        ((162, 3), (320, 3))
        >>> r = np.linalg.norm(V2, axis=1)    # the edges' midpoints pushed out to the sphere
        >>> round(float(r[:len(V)].mean()), 3), round(float(r[len(V):].mean()), 3)
        (1.0, 1.001)
        >>> round(float(np.linalg.norm(midpoint_subdivision(V, F)[0][len(V):], axis=1).mean()), 3)
        0.956
        """
        V, F, N = self._mesh
        VN, _ = midpoint_subdivision(np.hstack([V, N]), F, self.levels)
        N2 = VN[:, 3:] / np.linalg.norm(VN[:, 3:], axis=1, keepdims=True)
        return VN[:, :3] + self.h[:, None] * N2, self.F2

    def __call__(self, face, beta) -> np.ndarray:
        """The heights ``(k,)`` at barycentric points ``(face, beta)`` of the mesh."""
        f2, b2 = subdivided_points(face, beta, self.n_faces, self.levels)
        return np.einsum("kc,kc->k", b2, self.h[self.F2[f2]])

