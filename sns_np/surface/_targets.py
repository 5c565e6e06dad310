"""What a fit samples: a mesh through its spherical embedding, or an analytic surface map.

A target gives sphere points ``p`` with their surface points ``q`` and unit normals, in the
normalised frame (centred at the area centroid, scaled to area 4 pi), plus the frame itself
(``center``, ``scale``), the bounding-box diagonal and a fingerprint that a checkpoint must
match.
"""

from __future__ import annotations

import hashlib
from functools import cached_property

import numpy as np

from ..geometry import tangent_frame, tangent_jacobian
from ..geometry.chart import chart_jets
from ..options import check_smooth
from ..protocol import surface_jet
from ..sampling import uniform_sphere
from .losses import normals_from_tangents


class _MeshTarget:
    """Samples of a mesh and its spherical embedding, in the normalised frame."""

    #: how the sphere maps to the target (the automatic normal weight depends on it)
    parametrisation = "embedding"

    def __init__(self, V, F, Vs=None, check=True, verbose=True, smooth="phong",
                 crease_angle="none", positions=False):
        from .. import mesh
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F)
        if check:
            mesh.check(V, F)
        self.smooth, crease_angle = check_smooth(smooth, crease_angle)
        self.smooth_why = _SMOOTH_WHY[self.smooth]
        # the mesh's coarseness is measured here for "auto" creases, else on first use (the
        # automatic vertex_fraction and closest_normal_weight)
        # (``positions``: the fit may take a sampled surface by its positions, fit_mesh's
        # normal weight left to auto; "auto" then leaves a rippled mesh uncreased)
        auto = crease_angle == "auto" and self.smooth != "normals"
        sample = None
        if auto:
            self.phong_gap, self.normal_turn = phong_gap(V, F), mesh.normal_turn(V, F)
            if positions and self.smooth == "phong":
                self.curvature_jitter = mesh.curvature_jitter(V, F)
                sample = smooth_sampling(self.phong_gap, self.normal_turn, self.curvature_jitter)
        self.crease_angle, self.crease_why = _crease_choice(
            crease_angle, self.coarse if auto else None, self.smooth, sample)
        if Vs is None:
            Vs = mesh.spherical_embedding(V, F, verbose=verbose)[0]
        self.corr = mesh.Correspondence(V, F, Vs, crease_angle=self.crease_angle)
        areas = mesh.face_areas(V, F)
        self.face_area = areas
        self.face_centroid = V[F].mean(axis=1)
        self.area = float(areas.sum())
        self.center = (areas[:, None] * self.face_centroid).sum(axis=0) / self.area
        self.scale = float(np.sqrt(self.area / (4 * np.pi)))
        self.mean_face_area = 4 * np.pi / len(F)     # normalised units (total 4 pi)
        self.bbox_diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
        self.fingerprint = _fingerprint(V, F)
        self.heights = None
        if self.smooth == "normals":
            from ..options import NORMAL_HEIGHT_TIE
            levels = normal_height_levels(len(V), len(F))
            self.heights = mesh.NormalHeights(V, F, self.corr.N, levels=levels,
                                              tie=NORMAL_HEIGHT_TIE)
            self.smooth_why += (f"; heights on {levels} round(s) of midpoint subdivision "
                                f"({len(self.heights.h):,} unknowns, tie {NORMAL_HEIGHT_TIE:g}, "
                                f"solved in {self.heights.seconds:.1f} s)")
            if verbose:
                print(f"target: {self.smooth_why}", flush=True)
            self.fingerprint += f":normals:tie={NORMAL_HEIGHT_TIE:g}:levels={levels}"
        if self.smooth not in ("phong", "normals") or self.crease_angle is not None:
            self.fingerprint += f":{self.smooth}:creases={self.crease_angle}"
        self._nearest = None            # the ClosestPoint search, built on first use
        self.last_faces = None          # the faces of the last points drawn on the faces

    @cached_property
    def phong_gap(self):
        """The mesh's :func:`phong_gap`: how coarse it is for its size."""
        return phong_gap(self.corr.V, self.corr.F)

    @cached_property
    def normal_turn(self):
        """The mesh's :func:`~sns_np.mesh.normal_turn`: how coarse it is for its curvature."""
        from .. import mesh
        return mesh.normal_turn(self.corr.V, self.corr.F)

    @property
    def coarse(self):
        """``(coarse, why)``: :func:`coarseness` of this mesh."""
        return coarseness(self.phong_gap, self.normal_turn)

    @cached_property
    def curvature_jitter(self):
        """The mesh's :func:`~sns_np.mesh.curvature_jitter`: how smooth a sample it is."""
        from .. import mesh
        return mesh.curvature_jitter(self.corr.V, self.corr.F)

    @property
    def smooth_sample(self):
        """``(kind, why)``: :func:`smooth_sampling` of this mesh; never (``kind`` None) with a
        target other than the Phong points or with creases, which ask for the normals."""
        if self.smooth != "phong" or self.crease_angle is not None:
            return None, (f"the {self.smooth!r} target" + (
                f" with creases at {self.crease_angle:g} deg" if self.crease_angle else "")
                + ": its normals are followed")
        return smooth_sampling(self.phong_gap, self.normal_turn, self.curvature_jitter)

    def _targets(self, face, beta):
        q, nrm = self.corr.to_mesh(face, beta)
        if self.smooth == "phong":
            q = self.corr.phong_point(face, beta)
        elif self.smooth == "normals":
            q = q + self.heights(face, beta)[:, None] * nrm
        return (q - self.center) / self.scale, nrm

    def sample(self, n, rng):
        return self._points(*self.corr.sample_barycentric(n, rng))

    def sample_faces(self, face, rng):
        """Points uniform by area within the given faces ``(n,)``: ``(p, q, normals)``."""
        from ..mesh import uniform_barycentric
        return self._points(face, uniform_barycentric(len(face), rng))

    def sample_vertices(self, n, rng):
        """``n`` vertices drawn uniformly: ``(p, q, normals)`` at the vertices themselves,
        where the mesh's positions are exact (between them they are interpolated); the
        normal of a vertex on a crease is that of its first face's side."""
        i = rng.integers(0, len(self.corr.V), n)
        q = self.corr.V[i]
        if self.heights is not None:        # the subdivision's first vertices are the mesh's
            q = q + self.heights.h[i, None] * self.corr.N[i]
        return self.corr.Vs[i], (q - self.center) / self.scale, self.corr.N_target[i]

    @cached_property
    def sphere_density(self):
        """Each face's share of the surface's area over its share of the sphere's: the area
        element of the embedding's map in normalised units (total area 4 pi), ``(m,)``."""
        from ..mesh.spherical import spherical_triangle_areas
        sphere = spherical_triangle_areas(self.corr.Vs, self.corr.F)
        return (self.face_area / self.area) / (sphere / sphere.sum())

    def _points(self, face, beta):
        """``(p, q, normals)`` of the points ``beta`` of faces ``face`` (kept as
        ``last_faces``, for the fit's area weights)."""
        self.last_faces = face
        return (self.corr.to_sphere(face, beta), *self._targets(face, beta))

    def evaluate_at(self, p):
        return self._targets(*self.corr.locate(p))

    def nearest(self):
        """The :class:`~sns_np.mesh.closest.ClosestPoint` search of the mesh, built on first
        use (build it before handing ``closest`` to several threads)."""
        if self._nearest is None:
            from ..mesh.closest import ClosestPoint
            self._nearest = ClosestPoint(self.corr.V, self.corr.F)
        return self._nearest

    def closest(self, y):
        """Targets at the mesh point nearest each point ``y`` (n, 3) of the normalised frame:
        ``(q, normals)``, like ``sample``'s but independent of the parametrisation."""
        face, beta, _ = self.nearest().query(self.center + self.scale * np.asarray(
            y, dtype=np.float64), exact=False)
        return self._targets(face, beta)


class _ShapeTarget:
    """Samples of an analytic surface map S(p), uniform on the parameter sphere."""

    parametrisation = "exact"

    def __init__(self, shape):
        from ..quadrature import sphere_quadrature
        self.shape = shape
        P, w = sphere_quadrature(96)
        y, J = surface_jet(shape, P, 1)
        JR = tangent_jacobian(J, tangent_frame(P))
        dA = np.linalg.norm(np.cross(JR[:, :, 0], JR[:, :, 1]), axis=1) * w
        self.area = float(dA.sum())
        self.center = (dA[:, None] * y).sum(axis=0) / self.area
        self.scale = float(np.sqrt(self.area / (4 * np.pi)))
        self.bbox_diagonal = float(np.linalg.norm(y.max(axis=0) - y.min(axis=0)))
        self.fingerprint = f"shape:{type(shape).__name__}:{_fingerprint(y[:64], None)}"

    #: the icosphere level of the parameter sphere's cells, what an error-weighted draw
    #: weights (level 4: 5,120 cells, each drawn about 8 times in the sampler's running
    #: window at the detailed batch of 512)
    CELL_LEVEL = 4

    def sample(self, n, rng):
        return self.sample_jet(n, rng)[:3]

    @cached_property
    def _cells(self):
        from ..mesh import icosphere, spherical_triangle_areas
        V, F = icosphere(self.CELL_LEVEL)
        V = V / np.linalg.norm(V, axis=1, keepdims=True)
        c = V[F].sum(axis=1)
        return V, F, spherical_triangle_areas(V, F), c / np.linalg.norm(c, axis=1)[:, None]

    @property
    def face_area(self):
        """The areas of the parameter sphere's cells (geodesic triangles; they sum to 4 pi):
        a uniform draw on the sphere is a draw of cells by these areas."""
        return self._cells[2]

    @property
    def face_centroid(self):
        """The cells' centres (unit vectors)."""
        return self._cells[3]

    def sample_faces(self, face, rng, jets=False, second=False):
        """Points uniform on the sphere within the given cells ``(n,)``: ``(p, q, normals)``
        as :meth:`sample`, or with ``jets`` ``(p, q, normals, JT, ST)`` as
        :meth:`sample_jet`."""
        from ..mesh import uniform_in_spherical_triangles
        V, F = self._cells[:2]
        T = F[np.asarray(face)]
        p = uniform_in_spherical_triangles(V[T[:, 0]], V[T[:, 1]], V[T[:, 2]], rng)
        return (p, *self._jet(p, second)) if jets else (p, *self.evaluate_at(p))

    def sample_jet(self, n, rng, second=False):
        """``sample``'s points with the map's derivatives along ``tangent_frame(p)`` in the
        normalised frame, the exact data of the Jacobian and Hessian losses: ``(p, q,
        normals, JT, ST)``, JT (n, 3, 2); ST (n, 3, 2, 2) the second derivatives along the
        sphere ``S_ab = D2[e_a, e_b] - delta_ab J p`` with ``second``, else None. One jet of
        the map for all."""
        p = uniform_sphere(n, rng)
        return (p, *self._jet(p, second))

    def evaluate_at(self, p):
        return self._jet(p)[:2]

    def _jet(self, p, second=False):
        R = tangent_frame(p)
        if second:
            y, JR, _, S2 = chart_jets(self.shape, p, R, 2)
        else:
            (y, JR), S2 = chart_jets(self.shape, p, R, 1), None
        nrm, _ = normals_from_tangents(JR[:, :, 0], JR[:, :, 1], degenerate="zero")
        return ((y - self.center) / self.scale, nrm, JR / self.scale,
                None if S2 is None else S2 / self.scale)


#: what each position target is (the report's ``choices["smooth"]["why"]``)
_SMOOTH_WHY = {
    "phong": "the Phong tessellation of the mesh",
    "normals": "the surface over the mesh that follows its interpolated vertex normals",
    "none": "the mesh's flat triangles"}


def normal_height_levels(n_vertices, n_faces):
    """Rounds of midpoint subdivision of the "normals" target's heights: as many as keep its
    vertices within ``NORMAL_HEIGHT_UNKNOWNS``, at most ``NORMAL_HEIGHT_LEVELS``. A round
    adds a vertex per edge (3/2 per face of a closed mesh) and quadruples the faces.

    Examples
    --------
    >>> normal_height_levels(2930, 5856), normal_height_levels(21622, 43240)
    (3, 2)
    """
    from ..options import NORMAL_HEIGHT_LEVELS, NORMAL_HEIGHT_UNKNOWNS
    levels, n, m = 0, n_vertices, n_faces
    while levels < NORMAL_HEIGHT_LEVELS and n + 3 * m // 2 <= NORMAL_HEIGHT_UNKNOWNS:
        levels, n, m = levels + 1, n + 3 * m // 2, 4 * m
    return levels


def _crease_choice(creases, coarse, smooth="phong", sample=None):
    """The crease angle (degrees, or None for none) and why; ``coarse`` (the mesh's
    :func:`coarseness`) is read for "auto" only, and not with the "normals" target, which
    follows the vertex normals across every edge, nor for a rippled mesh that the fit may
    take by its positions (``sample``, :func:`smooth_sampling`'s answer, given then)."""
    from ..options import CREASE_ANGLE, check_creases
    creases = check_creases(creases)
    if creases == "none":
        return None, "given: the vertex normals interpolated everywhere"
    if creases != "auto":
        return creases, "given"
    if smooth == "normals":
        return None, ("none: the normal-following target follows the vertex normals across "
                      "every edge")
    if sample is not None and sample[0] == "rippled":
        return None, f"none: {sample[1]}; fitted by its positions, with no normals to crease"
    is_coarse, why = coarse
    if is_coarse:
        return CREASE_ANGLE, (f"{why}, whose vertex normals would round its sharp edges "
                              f"off over a triangle's width")
    return None, f"none: {why}, the vertex normals interpolated everywhere"


def coarseness(gap, turn):
    """``(coarse, why)``: whether a mesh with Phong gap ``gap`` (:func:`phong_gap`) and
    normal turn ``turn`` (:func:`~sns_np.mesh.normal_turn`) is coarse, too coarse for its
    interpolated targets to be followed between its vertices: its Phong tessellation stands
    more than ``CREASE_GAP`` of the diagonal off its triangles (coarse for its size), or its
    vertex normals turn by more than ``COARSE_TURN`` degrees across a median edge (coarse for
    its curvature, e.g. ripples a few edges wide on a fine mesh).

    Examples
    --------
    >>> coarseness(2e-3, 5.0)[0], coarseness(5e-4, 30.0)[0], coarseness(5e-4, 10.0)[0]
    (True, True, False)
    """
    from ..options import COARSE_TURN, CREASE_GAP
    said = (f"its Phong tessellation stands {gap:.2e} of the diagonal off its triangles and "
            f"its vertex normals turn by {turn:.1f} deg across a median edge")
    if gap > CREASE_GAP or turn > COARSE_TURN:
        return True, f"a coarse mesh ({said}: > {CREASE_GAP:g} or > {COARSE_TURN:g} deg)"
    return False, f"a fine mesh ({said}: <= {CREASE_GAP:g} and <= {COARSE_TURN:g} deg)"


def smooth_sampling(gap, turn, jitter):
    """``(kind, why)``: whether a mesh with Phong gap ``gap`` (:func:`phong_gap`), normal turn
    ``turn`` (:func:`~sns_np.mesh.normal_turn`) and curvature jitter ``jitter``
    (:func:`~sns_np.mesh.curvature_jitter`) samples a smooth surface at its vertices, which
    then lead the fit while its interpolated normals are only an estimate; ``kind`` is

    * ``"fine"``: a fine mesh (not coarse by :func:`coarseness`) whose jitter is at most
      ``SAMPLE_JITTER``, a surface smooth at its vertex spacing;
    * ``"rippled"``: coarse for its curvature alone, its normals turning by more than
      ``COARSE_TURN`` degrees across a median edge while its Phong tessellation stays within
      ``CREASE_GAP`` of its triangles: ripples a few edges wide, sampled by the vertices,
      between which no interpolated normal is to be trusted;
    * ``None`` otherwise (coarse for its size, or detail as fine as its vertices).

    Examples
    --------
    >>> [smooth_sampling(g, t, j)[0] for g, t, j in ((3e-4, 10.0, 0.07), (3e-4, 10.0, 0.23),
    ...                                                (9e-4, 31.0, 0.46), (2e-3, 5.0, 0.0))]
    ['fine', None, 'rippled', None]
    """
    from ..options import COARSE_TURN, CREASE_GAP, SAMPLE_JITTER
    coarse, why = coarseness(gap, turn)
    if gap <= CREASE_GAP and turn > COARSE_TURN:
        return "rippled", (f"{why}: coarse for its curvature alone, ripples sampled at its "
                           f"vertices; they lead, its interpolated normals are guesses")
    if coarse:
        return None, f"{why}: not a fine sample"
    said = f"its mean curvature changes by {jitter:.3f} of its size from vertex to vertex"
    if jitter <= SAMPLE_JITTER:
        return "fine", (f"a fine sample of a smooth surface ({said}: <= {SAMPLE_JITTER:g}); "
                        f"its vertices lead, its interpolated normals are only an estimate")
    return None, f"detail at its vertex spacing ({said}: > {SAMPLE_JITTER:g})"


def phong_gap(V, F, n=20000):
    """How far the Phong tessellation of a mesh (shape factor 0.75, the fit's position
    targets) stands off its flat triangles: the mean distance at ``n`` points uniform by
    area (seeded), relative to the bounding-box diagonal. About the chordal error of the
    triangles where the mesh samples a smooth surface; at a sharp edge, how far a surface
    that follows the vertex normals across it rounds it off."""
    from ..mesh import sample_surface, vertex_normals
    from ..mesh.correspondence import phong_offset
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    face, beta = sample_surface(V, F, n, rng=0)
    N = vertex_normals(V, F)
    _, offset = phong_offset(V[F[face]], N[F[face]], beta)
    diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    return float(0.75 * np.linalg.norm(offset, axis=1).mean() / diagonal)


def _fingerprint(V, F):
    h = hashlib.sha256(np.ascontiguousarray(V, dtype=np.float64).tobytes())
    if F is not None:
        h.update(np.ascontiguousarray(F, dtype=np.int64).tobytes())
    return h.hexdigest()[:16]

