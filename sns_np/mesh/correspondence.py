"""Sphere <-> mesh correspondence through a fold-free spherical embedding.

A point of surface triangle ``f`` with barycentric coordinates ``beta`` corresponds to the sphere
point ``p = (beta_0 a + beta_1 b + beta_2 c) / |...|``, where ``a, b, c`` are the embedded
corners of ``f`` (paper, Section 3: "we extend the embedding to a continuous embedding by
employing barycentric coordinates"). Since a fold-free embedding tiles the sphere with the
central projections of its chord triangles, this is a bijection; its inverse is the gnomonic
barycentric coordinate of ``p`` in the spherical triangle that contains it.

Two defects of the reference implementation are avoided here: faces are drawn with probability
proportional to their area (not area squared), and sphere points are projected onto the sphere
(not left on the chord triangle, where ``|p| < 1``).
"""

from __future__ import annotations

import numpy as np

from .._validation import as_generator, as_points, check_positive_int
from ..errors import ShapeError
from ._arrays import as_mesh
from .errors import EmbeddingError
from .operators import corner_normals, face_areas, vertex_normals
from .spherical import SphereLocator, orientation_determinants

__all__ = ["sample_surface", "uniform_barycentric", "phong_offset", "Correspondence"]


def uniform_barycentric(n: int, rng=None) -> np.ndarray:
    """Barycentric coordinates of ``n`` points uniform on a triangle.

    Uses ``(1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2)`` with ``r1, r2`` uniform on [0, 1)
    (Osada et al. 2002).

    Returns
    -------
    beta : (n, 3) float array, non-negative rows summing to 1

    Examples
    --------
    >>> beta = uniform_barycentric(1000, rng=0)
    >>> beta.shape, bool(np.allclose(beta.sum(axis=1), 1.0)), bool((beta >= 0).all())
    ((1000, 3), True, True)

    References
    ----------
    R. Osada, T. Funkhouser, B. Chazelle and D. Dobkin, "Shape distributions", ACM Transactions
    on Graphics 21(4), 2002.
    """
    g = as_generator(rng)
    r = g.random((2, n))
    s = np.sqrt(r[0])
    return np.stack([1.0 - s, s * (1.0 - r[1]), s * r[1]], axis=1)


def _draw(cum, n, g):
    """Face indices with probability proportional to the increments of ``cum``."""
    f = np.searchsorted(cum, g.random(n) * cum[-1], side="right")
    return np.minimum(f, cum.size - 1)


def sample_surface(V, F, n: int, rng=None):
    """Points drawn uniformly by area on a triangle mesh.

    A face is chosen with probability ``A_f / sum A`` and a point uniformly inside it, so the
    points are uniform on the surface.

    Parameters
    ----------
    V : (k, 3) float array
    F : (m, 3) int array
    n : int
        Number of points.
    rng : None, int or numpy.random.Generator
        ``None`` is seed 0 (reproducible).

    Returns
    -------
    face : (n,) int array
    beta : (n, 3) float array, barycentric coordinates in ``F[face]``

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> face, beta = sample_surface(V, F, 5, rng=1)
    >>> face.shape, beta.shape
    ((5,), (5, 3))
    >>> q = (beta[:, :, None] * V[F[face]]).sum(axis=1)      # the points themselves
    """
    V, F = as_mesh(V, F)
    n = check_positive_int(n, "n", minimum=0)
    g = as_generator(rng)
    cum = np.cumsum(face_areas(V, F))
    face = _draw(cum, n, g)
    return face, uniform_barycentric(n, g)


def phong_offset(P, N, beta):
    """The flat points ``q = sum_i beta_i P_i`` (k, 3) of triangles with corners ``P`` (k, 3, 3)
    and corner normals ``N`` (k, 3, 3), and the offset (k, 3) that takes them to Phong
    tessellation with shape factor 1: ``sum_i beta_i (pi_i(q) - q)``,
    ``pi_i(q) = q - ((q - P_i) . N_i) N_i`` (:meth:`Correspondence.phong_point`).

    Examples
    --------
    >>> P = np.array([[[1.0, 0, 0], [0, 1, 0], [0, 0, 1]]])      # a corner of the octahedron
    >>> q, offset = phong_offset(P, P, np.full((1, 3), 1 / 3))    # normals radial
    >>> bool(np.linalg.norm(q + offset) > np.linalg.norm(q))      # lifted towards the sphere
    True
    """
    q = beta[:, 0, None] * P[:, 0] + beta[:, 1, None] * P[:, 1] + beta[:, 2, None] * P[:, 2]
    offset = np.zeros_like(q)
    for i in range(3):
        h = np.einsum("ij,ij->i", q - P[:, i], N[:, i])
        offset -= (beta[:, i] * h)[:, None] * N[:, i]
    return q, offset


class Correspondence:
    """The continuous map between a mesh and its spherical embedding, both ways.

    Parameters
    ----------
    V : (n, 3) float array, the surface mesh
    F : (m, 3) int array
    Vs : (n, 3) float array, a fold-free spherical embedding of ``V`` (unit vectors, every
        ``det[a, b, c] > 0``), e.g. from :func:`sns_np.mesh.spherical_embedding`
    normals : {"angle", "area"}
        Weighting of the vertex normals that are interpolated to give smooth target normals.
    crease_angle : float in (0, 180], optional
        In degrees: interpolate each face's corner normals (:func:`~sns_np.mesh.
        corner_normals`), which do not average across edges sharper than this, instead of
        the vertex normals; ``None`` (default) interpolates the vertex normals everywhere.

    Attributes
    ----------
    area : float
        Surface area of the mesh.
    N : (n, 3) float array
        The unit vertex normals.
    N_target : (n, 3) float array
        The normal a sample at a vertex itself takes: the vertex normal, or with a crease
        angle the corner normal of the vertex's first face (a vertex on a crease has one
        per side).

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> Vs, F = icosphere(3)
    >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
    >>> p, q, nrm = C.sample(2048, rng=0)
    >>> bool(np.allclose(np.linalg.norm(p, axis=1), 1.0))
    True
    >>> q2, _ = C.mesh_point(p)
    >>> bool(np.allclose(q2, q))
    True
    """

    def __init__(self, V, F, Vs, *, normals: str = "angle", crease_angle=None):
        V, F = as_mesh(V, F)
        Vs = as_points(Vs, "Vs")
        if Vs.shape != V.shape:
            raise ShapeError(f"Vs must have the shape of V {V.shape}, got {Vs.shape}")
        r = np.linalg.norm(Vs, axis=1)
        if np.abs(r - 1.0).max() > 1e-6:
            k = int(np.argmax(np.abs(r - 1.0)))
            raise ShapeError(f"Vs must be unit vectors; vertex {k} has |Vs| = {r[k]:.12g}")
        det = orientation_determinants(Vs, F)
        if not (det > 0).all():
            bad = np.flatnonzero(det <= 0)
            raise EmbeddingError(
                f"the spherical embedding folds {bad.size} triangle(s) (det[a, b, c] <= 0), "
                f"e.g. face {int(bad[0])}; expected a fold-free embedding")
        self.V, self.F, self.Vs = V, F, Vs
        self.N = vertex_normals(V, F, weighting=normals)
        self.crease_angle = None if crease_angle is None else float(crease_angle)
        corners = corner_normals(V, F, crease_angle, weighting=normals)
        # a vertex's own normal target: the corner normal of its first face (the vertex
        # normal where no crease meets it)
        used, first = np.unique(F.ravel(), return_index=True)
        self.N_target = self.N.copy()
        self.N_target[used] = corners.reshape(-1, 3)[first]
        A = face_areas(V, F)
        self.area = float(A.sum())
        self._cum = np.cumsum(A)
        # corners gathered once, [mesh | sphere | normal] side by side, so that a batch of
        # samples costs one fancy-indexing pass: _corners[f, k] = (V, Vs, N)[F[f, k]] (N the
        # corner normal with a crease angle)
        self._corners = np.ascontiguousarray(np.concatenate([V[F], Vs[F], corners], axis=2))
        self._locator = None

    @staticmethod
    def _combine(corners, face, beta):
        C = corners[face]
        return (beta[:, 0, None] * C[:, 0] + beta[:, 1, None] * C[:, 1]
                + beta[:, 2, None] * C[:, 2])

    @staticmethod
    def _unit(x):
        return x / np.linalg.norm(x, axis=1, keepdims=True)

    def to_sphere(self, face, beta) -> np.ndarray:
        """Sphere points ``p`` (k, 3), exactly unit, of barycentric points ``(face, beta)``.

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> Vs, F = icosphere(2)
        >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
        >>> p = C.to_sphere(np.array([0, 5]), np.full((2, 3), 1 / 3))
        >>> bool(np.allclose(np.linalg.norm(p, axis=1), 1.0))
        True
        """
        return self._unit(self._combine(self._corners[:, :, 3:6], face, beta))

    def to_mesh(self, face, beta):
        """Mesh points ``q`` (k, 3) and unit interpolated normals (k, 3) of ``(face, beta)``.

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> Vs, F = icosphere(2)
        >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
        >>> q, n = C.to_mesh(np.array([0]), np.array([[1.0, 0.0, 0.0]]))    # a corner
        >>> bool(np.allclose(q[0], C.V[F[0, 0]])), bool(np.allclose(n[0], C.N[F[0, 0]]))
        (True, True)
        """
        X = self._combine(self._corners, face, beta)
        return X[:, 0:3], self._unit(X[:, 6:9])

    def phong_point(self, face, beta, alpha: float = 0.75) -> np.ndarray:
        """Points ``(k, 3)`` of the Phong-tessellated surface at barycentric points.

        The flat point ``q = sum_i beta_i v_i`` is projected onto the tangent plane of each
        corner (``pi_i(q) = q - ((q - v_i) . n_i) n_i``, with the corners' vertex normals) and
        the projections are blended with the same weights:
        ``q* = (1 - alpha) q + alpha sum_i beta_i pi_i(q)`` (Boubekeur and Alexa, "Phong
        Tessellation", SIGGRAPH Asia 2008). The result interpolates the vertices, is tangent
        there to the vertex normals and bulges between them like the surface the mesh samples:
        on an icosphere of level 2 its mean distance to the sphere is 0.46 of the flat
        triangles' (tests/test_surface.py). The flat triangles' chordal error is what a network
        fitted to them reproduces as curvature along the edges.

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> V, F = icosphere(2)
        >>> C = Correspondence(V, F, V)
        >>> face, beta = C.sample_barycentric(2000, rng=0)
        >>> flat = np.abs(np.linalg.norm(C.to_mesh(face, beta)[0], axis=1) - 1).mean()
        >>> phong = np.abs(np.linalg.norm(C.phong_point(face, beta), axis=1) - 1).mean()
        >>> bool(phong < 0.6 * flat)                     # closer to the sphere it samples
        True
        """
        C = self._corners[face]
        q, offset = phong_offset(C[:, :, 0:3], C[:, :, 6:9], beta)
        return q + alpha * offset

    def sample_barycentric(self, n: int, rng=None):
        """Faces ``(n,)`` and barycentric coordinates ``(n, 3)`` of ``n`` points uniform by
        area on the mesh (the draw that :meth:`sample` makes).

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> Vs, F = icosphere(2)
        >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
        >>> face, beta = C.sample_barycentric(5, rng=1)
        >>> p, q, n = C.sample(5, rng=1)                 # the same draw
        >>> bool(np.allclose(C.to_sphere(face, beta), p))
        True
        """
        n = check_positive_int(n, "n", minimum=0)
        g = as_generator(rng)
        face = _draw(self._cum, n, g)
        return face, uniform_barycentric(n, g)

    def sample(self, n: int, rng=None):
        """Draw ``n`` points uniformly by area on the mesh, with their sphere points.

        Parameters
        ----------
        n : int
        rng : None, int or numpy.random.Generator
            Pass one Generator through a fitting loop; ``None`` is seed 0.

        Returns
        -------
        p : (n, 3) float array, sphere points, ``|p| = 1``
        q : (n, 3) float array, the corresponding mesh points
        normals : (n, 3) float array, unit, barycentric interpolation of vertex normals

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> Vs, F = icosphere(2)
        >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
        >>> p, q, n = C.sample(100, rng=0)
        >>> p.shape, q.shape, bool(np.allclose(np.linalg.norm(n, axis=1), 1.0))
        ((100, 3), (100, 3), True)
        """
        face, beta = self.sample_barycentric(n, rng)
        X = self._combine(self._corners, face, beta)
        return self._unit(X[:, 3:6]), X[:, 0:3], self._unit(X[:, 6:9])

    @property
    def locator(self) -> SphereLocator:
        """The point-location structure on the embedding (built on first use)."""
        if self._locator is None:
            self._locator = SphereLocator(self.Vs, self.F)
        return self._locator

    def locate(self, p):
        """Triangle and barycentric coordinates of sphere points.

        Parameters
        ----------
        p : (k, 3) float array, unit vectors

        Returns
        -------
        face : (k,) int array
        beta : (k, 3) float array, non-negative, rows sum to 1

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> Vs, F = icosphere(2)
        >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
        >>> face, beta = C.sample_barycentric(50, rng=0)
        >>> f2, b2 = C.locate(C.to_sphere(face, beta))          # the inverse of to_sphere
        >>> bool(np.array_equal(f2, face)), bool(np.allclose(b2, beta))
        (True, True)
        """
        return self.locator.locate(p)

    def mesh_point(self, p):
        """Mesh points and smooth normals corresponding to sphere points ``p`` (k, 3).

        Returns
        -------
        q : (k, 3) float array
        normals : (k, 3) float array, unit

        Examples
        --------
        >>> from sns_np.mesh import icosphere
        >>> Vs, F = icosphere(2)
        >>> C = Correspondence(Vs * [1.0, 1.0, 2.0], F, Vs)
        >>> q, n = C.mesh_point(np.array([[0.0, 0.0, 1.0]]))     # the north pole
        >>> q.round(6).tolist()
        [[0.0, 0.0, 2.0]]
        """
        face, beta = self.locate(p)
        return self.to_mesh(face, beta)
