"""Fitting quality and time: one table over the shared meshes and the paper's shapes.

Run::

    python benchmarks/fit_quality.py                         # every case, default options
    python benchmarks/fit_quality.py spot max                # some cases
    python benchmarks/fit_quality.py spot --time-budget 1800 # any fitting option
    python benchmarks/fit_quality.py dtype --steps 150       # float32 vs float64 training
    python benchmarks/fit_quality.py init --steps 200        # ridge read-out vs random init
    python benchmarks/fit_quality.py detail                  # detail measures, curvature jitter
    python benchmarks/fit_quality.py loop spot max           # smooth surfaces near the mesh, scored
    python benchmarks/fit_quality.py models A.npz flower=B.npz  # saved fits: roughness, drift
    python benchmarks/fit_quality.py path/to/mesh.obj        # any closed genus-0 mesh file

Cases:

* every mesh of ``../shared/data/meshes`` (spot, max, decimated_max, armadillo, the issue's
  four; spot_quad, spot_control, flower3, flower5, icosphere2, icosphere3, uv_sphere) and the
  built-in ellipsoid mesh: measured against the mesh itself. ``dist`` is the two-sided mean distance
  relative to the bounding-box diagonal: the mean of (surface -> mesh, exact point-to-triangle
  distance at 20,000 held-out surface points) and (mesh vertices -> surface, each vertex
  projected onto the fitted surface from its nearest point in a dense sample by Gauss-Newton
  steps on the sphere), so a surface that skips a feature is caught. ``nrm`` is the mean angle
  between the fitted normal and the mesh's interpolated (angle-weighted) vertex normal at the
  closest mesh point. ``dense_m2s`` is the mesh-to-surface half over the quarter of the
  vertices with the smallest share of the area (fingers, faces): a fit that passes over small
  features is far from them (Stein's humans: 20-25 times the sparsest quarter). Needs
  libigl. The meshes whose vertices lie on a known surface (the flowers, the spheres) are
  also compared with it, as the next item says. The path of any
  mesh file (``.obj``, ``.off``, ``.ply``, ``.stl``) is a case too, measured the same way.
* ``bobble5``, ``spike5``: the paper's BOBBLE and SPIKE meshed at icosphere level 5 (10,242
  vertices) and fitted as meshes (and flower3, flower5, the spheres); ``flower``,
  ``bobble``, ``spike``, ``tree``: ``fit_shape`` on the exact maps. All are compared with the
  exact geometry at the closest point of the analytic surface (found by Gauss-Newton from the
  radial direction), at points more than 0.15 rad from the poles: normal angle, and mean |H|
  and |K| errors relative to the mean |truth|. For the meshes, libigl's
  ``principal_curvature`` (radius 2) on the same mesh is printed beside it (the issue's
  baseline), scored at the mesh vertices, where the mesh is exact; the fit's errors at the
  surface points nearest the vertices (``vtx_*``) are scored at the same places. For
  ``fit_shape`` the same errors are also printed at the same sphere point (``same_*``; its
  parametrisation is the shape's own), the kinder measure: it does not see a surface shifted
  along itself.

* ``cube``, ``jack``, ``cylinder`` (``cad_shapes.py``): meshes with sharp edges and flat
  faces, built here, measured against the mesh as above and, more than 0.1 from their edges,
  against their closed form: ``exact_nrm`` the normal angle, ``flat_H`` the mean |H - H_true|
  (0 on the flat parts, 1/(2 R) on the cylinder's side) times the radius of the sphere of the
  same area (a sphere's H would read 1).

Every fitted case also prints ``rough``, the roughness of its mean curvature (``models``
below): on a mesh of a smooth surface it is the truth's (SPIKE at level 5: 0.010), on a
detailed mesh it grows as a longer fit copies the facets (docs/fitting.md, "The curvature's
roughness").

``loop``: no fit; the mesh's Loop subdivision surface (two levels, libigl) on the same
measures (``dist``, ``nrm``): what a classical smooth surface near the mesh reaches against
the mesh's own interpolated normals, the reference for the normal goal. Then a surface made
to follow those normals (``normal_following``: the mesh's midpoint subdivision, three
levels, moved along the normals by the least-squares height field whose surface has them,
:class:`sns_np.mesh.NormalHeights`, the target of ``fit_mesh(smooth="normals")``), the same
measures: how far a surface near the mesh can follow its normals, which are not the normals
of any one surface; held at the mesh's vertices with the ties ``TIES`` (1e-3 follows the
normals, 3e-2 the fit's, 1 holds the vertices), the trade between the two measures such
surfaces reach, which a fit's (``dist``, ``nrm``) can be read against. For ``bobble5`` and
``spike5``: how far the mesh's interpolated normals and its Loop surface's are from the exact
shape's (closest point, away from the poles), what a fit that follows the mesh can know.

``models``: no fit; saved models (``--out``) scored by the roughness of their mean curvature
(the mean of ``|H(p) - H(p')|`` over pairs of sphere points 1e-3 rad apart, in a random
direction, relative to the mean ``|H|``: streaks and wrinkles raise it). A model named
``SHAPE=PATH`` (``flower=B.npz``), a ``fit_shape`` of a paper shape, is also split into where
its points are: the distance to the exact point at the same sphere point, its parts along the
normal and along the surface, and how much the exact H differs between the same point and the
closest one (the part of the closest-point error that the drift alone makes).

Nothing is asserted; timings on a shared machine are noisy, so compare them within one run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from cad_shapes import CAD, cad_mesh, exact_away_from_edges  # noqa: E402

from sns_np.geometry import differential_quantities, tangent_frame  # noqa: E402
from sns_np.mesh import (  # noqa: E402
    check,
    curvature_jitter,
    face_areas,
    load,
    mass_matrix,
    sample_surface,
    spherical_embedding,
)
from sns_np.mesh.operators import vertex_normals  # noqa: E402
from sns_np.options import MESH_SMOOTHING, check_creases  # noqa: E402
from sns_np.protocol import surface_jet  # noqa: E402
from sns_np.sampling import uniform_sphere  # noqa: E402
from sns_np.surface import fit_mesh, fit_shape  # noqa: E402

#: every mesh of ../shared/data/meshes, by case name
MESHES = {"spot": "spot_triangulated.obj", "max": "max10606.obj",
          "decimated_max": "decimated_max.obj", "armadillo": "armadillo21622.obj",
          "spot_quad": "spot_quadrangulated.obj", "spot_control": "spot_control_mesh.obj",
          "flower3": "flower_mesh3.obj", "flower5": "flower_mesh5.obj",
          "icosphere2": "icosphere2.obj", "icosphere3": "icosphere3.obj",
          "uv_sphere": "uv_sphere.obj"}
#: the shared meshes whose vertices lie on a known surface (README of the shared meshes)
EXACT = {"flower3": ("flower", None), "flower5": ("flower", None),
         "icosphere2": ("sphere", 1.0), "icosphere3": ("sphere", 1.0),
         "uv_sphere": ("sphere", 0.7)}
#: coarse versions of shared meshes (libigl's qslim to this many vertices, at run time): the
#: low end of the vertex counts a user brings
COARSE = {"spot1000": ("spot", 1000), "armadillo1200": ("armadillo", 1200)}
ANALYTIC_MESHES = ("bobble5", "spike5")
SHAPES = ("flower", "bobble", "spike", "tree")
ALL = (*MESHES, *COARSE, "ellipsoid", *ANALYTIC_MESHES, *SHAPES, *CAD)
SHARED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data",
                      "meshes")
POLE = 0.15
#: the ties at the mesh's vertices of the surfaces that follow its normals (``loop``;
#: ``normal_following``; until session 54 ties to the triangles' mean, 1e-6, 1e-3, 1e-2)
TIES = (1e-3, 3e-2, 1.0)


def _is_mesh_file(case):
    """A case that names an existing mesh file (any format ``sns_np.mesh.load`` reads)."""
    return os.path.splitext(case)[1].lower() in (".obj", ".off", ".ply", ".stl") and \
        os.path.isfile(case)


def fit_options(args):
    keys = ("width", "depth", "steps", "batch", "time_budget", "dtype", "lr", "lr_min",
            "input_scale", "normal_weight", "smooth", "creases", "sampling", "optimizer",
            "vertex_fraction", "jacobian_weight", "hessian_weight", "tangent_weight",
            "closest_after", "anchor_weight", "closest_normal_weight",
            "second_moment_decay", "normal_huber", "area_weight_max", "seed")
    return {k: getattr(args, k) for k in keys if getattr(args, k) is not None}


# ------------------------------------------------------------------------------ measures

def _off_poles(p):
    """The sphere points more than POLE rad from both poles (a boolean mask)."""
    return np.arccos(np.clip(np.abs(p[:, 2]), 0, 1)) > POLE


def _project(S, x, p, iters=4):
    """Sphere points whose image under S is nearest to x, by Gauss-Newton from p; each point
    keeps the nearest of its iterates, the start included (a step can overshoot where the
    surface turns within it: on a thin blade, steps from the right point ended 0.4 of the
    diagonal away)."""
    p = np.array(p, dtype=np.float64)
    best, best_d = p.copy(), np.full(len(p), np.inf)
    for it in range(iters + 1):
        y, J = surface_jet(S, p, 1)
        d2 = ((x - y) ** 2).sum(axis=1)
        nearer = d2 < best_d
        best[nearer], best_d[nearer] = p[nearer], d2[nearer]
        if it == iters:
            return best
        R = tangent_frame(p)
        JR = np.einsum("kia,kab->kib", J, R)
        G = np.einsum("kia,kib->kab", JR, JR) + 1e-14 * np.eye(2)
        d = np.linalg.solve(G, np.einsum("kia,ki->ka", JR, x - y)[..., None])[..., 0]
        p = p + np.einsum("kab,kb->ka", R, d)
        p /= np.linalg.norm(p, axis=1, keepdims=True)


def _against_mesh(X, n, V, F):
    """Distances of points X to the mesh and the angles (degrees) between the normals n and
    the mesh's interpolated (angle-weighted) vertex normal at the closest mesh point."""
    import igl
    F64 = np.asarray(F, np.int64)
    N = vertex_normals(V, F, weighting="angle")
    d2, face, C = igl.point_mesh_squared_distance(X, V, F64)
    T = V[F64[face]]
    beta = igl.barycentric_coordinates(C, T[:, 0].copy(), T[:, 1].copy(), T[:, 2].copy())
    nm = np.einsum("kc,kci->ki", beta, N[F64[face]])
    nm /= np.linalg.norm(nm, axis=1, keepdims=True)
    return np.sqrt(d2), np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", nm, n), -1, 1)))


def nearest_parameters(S, X, n_dense=100_000, start=None):
    """The sphere points whose surface points are nearest the points X: the nearest of a
    dense sample, then Gauss-Newton steps on the sphere. With ``start`` (sphere points, one
    per point of X: a mesh's embedding) the steps also run from there, and each point keeps
    the nearer of the two results. A uniform sample of the sphere misses a part that the
    embedding squeezes into a tiny patch (a horse's legs at e^-11 of their share: 100,000
    points put none there), so without it such a part would read as missing from the
    surface; either result is a point of the surface, so the distance is never
    underestimated."""
    from scipy.spatial import cKDTree
    pd = uniform_sphere(n_dense, rng=6)
    _, k = cKDTree(S(pd)).query(X)
    p = _project(S, X, pd[k])
    if start is not None:
        q = _project(S, X, np.asarray(start, dtype=np.float64))
        nearer = np.linalg.norm(S(q) - X, axis=1) < np.linalg.norm(S(p) - X, axis=1)
        p[nearer] = q[nearer]
    return p


def mesh_fidelity(S, V, F, n=20000, n_dense=100_000, Vs=None):
    """Two-sided mean distance (relative to the bbox diagonal) and normal angle at the
    closest mesh point, means over the surface's area; None without libigl. ``Vs``: the
    mesh's embedding, a second start of the vertices' projections (``nearest_parameters``)."""
    try:
        import igl  # noqa: F401
    except ImportError:
        return None
    V = np.asarray(V, np.float64)
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    dq = differential_quantities(S, uniform_sphere(n, rng=5))
    d, ang = _against_mesh(dq.x, dq.n, V, F)
    # means over the fitted surface's area (uniform sphere points, each weighted by its area
    # element), whatever the parametrisation; the mesh's side, over its vertices
    w = dq.area_element / dq.area_element.sum()
    d_back = np.linalg.norm(S(nearest_parameters(S, V, n_dense, Vs)) - V, axis=1)
    # the mesh side where the mesh is finest (the quarter of the vertices with the smallest
    # share of the area: fingers, faces), which a fit that skips small features leaves far
    share = mass_matrix(V, F, "barycentric").diagonal()
    dense = share <= np.quantile(share, 0.25)
    return {"surface_to_mesh": float(w @ d / diag),
            "mesh_to_surface": float(d_back.mean() / diag),
            "dense_m2s": float(d_back[dense].mean() / diag),
            "dist": float((w @ d + d_back.mean()) / (2 * diag)),
            "nrm": float(w @ ang), "nrm_median": _weighted_median(ang, w)}


def _weighted_median(x, w):
    """The median of the values ``x`` with weights ``w`` (summing to 1)."""
    o = np.argsort(x)
    return float(x[o][np.searchsorted(np.cumsum(w[o]), 0.5)])


def loop_reference(V, F, levels=2, n=20000):
    """The same measures for the mesh's Loop subdivision surface (``levels`` rounds, libigl):
    what a classical smooth surface near the mesh reaches against its interpolated normals."""
    import igl
    return refined_reference(V, F, *igl.loop(np.asarray(V, np.float64),
                                             np.asarray(F, np.int64), levels), n)


def normal_following(V, F, levels=3, ties=(3e-2,)):
    """The surfaces that follow the mesh's interpolated normals, one per ``tie`` at its
    vertices (the library's :class:`sns_np.mesh.NormalHeights` on ``levels`` rounds of
    midpoint subdivision, the target of ``fit_mesh(smooth="normals")``): ``([V2 for each
    tie], F2)``. A small tie follows the normals, a large one holds the vertices: a sweep of
    ``ties`` traces the trade between the two measures that such surfaces reach."""
    from sns_np.mesh import NormalHeights
    V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
    N = vertex_normals(V, F, weighting="angle")
    meshes = [NormalHeights(V, F, N, levels=levels, tie=tie).mesh() for tie in ties]
    return [V2 for V2, _ in meshes], meshes[0][1]


def refined_reference(V, F, V2, F2, n=20000):
    """``dist`` and ``nrm`` of a finer mesh (V2, F2) near the mesh, its own angle-weighted
    vertex normals interpolated: what that surface reaches on a fit's measures."""
    import igl
    V = np.asarray(V, np.float64)
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    f, b = sample_surface(V2, F2, n, rng=5)
    N2 = vertex_normals(V2, F2, weighting="angle")
    X = np.einsum("kc,kci->ki", b, V2[F2[f]])
    nx = np.einsum("kc,kci->ki", b, N2[F2[f]])
    nx /= np.linalg.norm(nx, axis=1, keepdims=True)
    d, ang = _against_mesh(X, nx, V, F)
    d_back = np.sqrt(igl.point_mesh_squared_distance(V, V2, F2)[0])
    return {"dist": float((d.mean() + d_back.mean()) / (2 * diag)), "nrm": float(ang.mean()),
            "nrm_median": float(np.median(ang))}


def analytic_errors(S, shape, n=20000, at="closest", p=None):
    """Normal angle, relative mean |H| and |K| errors against the exact shape, more than
    POLE rad from the poles.

    ``at="closest"``: at the closest point of the exact surface (the geometric comparison);
    ``at="same"``: at the same sphere point, which only makes sense for ``fit_shape``, whose
    parametrisation is the shape's own. The second is the kinder measure: a surface shifted
    along itself keeps its normals at the same parameter but not at the same place.
    ``p``: the sphere points to compare at (default: ``n`` uniform ones).
    """
    if p is None:
        p = uniform_sphere(n, rng=11)
    dS = differential_quantities(S, p)
    if at == "closest":
        p = _project(shape, dS.x, dS.x / np.linalg.norm(dS.x, axis=1, keepdims=True), iters=6)
    dT = differential_quantities(shape, p)
    m = _off_poles(p)
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", dS.n, dT.n), -1, 1)))
    return {"nrm": float(ang[m].mean()),
            "H": float(np.abs(dS.H - dT.H)[m].mean() / np.abs(dT.H[m]).mean()),
            "K": float(np.abs(dS.K - dT.K)[m].mean() / np.abs(dT.K[m]).mean())}


def libigl_errors(shape, V, F, P, radius=2):
    """The same errors for libigl's principal_curvature at the mesh vertices (parameters P)."""
    try:
        import igl
    except ImportError:
        return None
    F64 = np.asarray(F, np.int64)
    _, _, kmax, kmin = igl.principal_curvature(V, F64, radius=radius)[:4]
    N = igl.per_vertex_normals(V, F64)
    dT = differential_quantities(shape, P)
    m = np.arccos(np.clip(np.abs(P[:, 2]), 0, 1)) > POLE
    H = (kmax + kmin) / 2
    if np.abs(H - dT.H)[m].mean() > np.abs(-H - dT.H)[m].mean():
        H = -H                                               # libigl's sign convention
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", N, dT.n), -1, 1)))
    return {"nrm": float(ang[m].mean()),
            "H": float(np.abs(H - dT.H)[m].mean() / np.abs(dT.H[m]).mean()),
            "K": float(np.abs(kmax * kmin - dT.K)[m].mean() / np.abs(dT.K[m]).mean())}


# ------------------------------------------------------------------------------ cases

def _shape(name, radius=None):
    from sns_np import shapes
    if name == "sphere":
        return shapes.Sphere(radius)
    return {"flower": shapes.Flower, "bobble": shapes.Bobble, "spike": shapes.Spike,
            "tree": shapes.Tree}[name]()


def case_mesh(case, shared=SHARED):
    """The mesh of a mesh case, ``(V, F, shape)``: ``shape`` the analytic surface its
    vertices lie on, or None."""
    if case == "ellipsoid":
        from sns_np.shapes import Ellipsoid
        return (*Ellipsoid(1.0, 1.3, 0.7).mesh(4), None)
    if case in ANALYTIC_MESHES:
        shape = _shape(case[:-1])
        return (*shape.mesh(5), shape)
    if case in CAD:
        return (*cad_mesh(case), None)
    if _is_mesh_file(case):              # a user's mesh: scored against itself only
        return (*load(case)[:2], None)
    if case in COARSE:                   # scored against the coarse mesh itself
        import igl
        name, n = COARSE[case]
        V, F = load(os.path.join(shared, MESHES[name]))[:2]
        U, G = igl.qslim(V, F, 2 * n - 4)[:2]       # a closed genus-0 mesh has 2 n - 4 faces
        return U, G, None
    V, F = load(os.path.join(shared, MESHES[case]))[:2]
    return V, F, _shape(*EXACT[case]) if case in EXACT else None


def run_case(case, args):
    """Fit one case; returns the table row (a dict)."""
    opts = fit_options(args)
    row = {"case": case}
    t0 = time.perf_counter()
    if case in SHAPES:
        shape = _shape(case)
        opts.pop("vertex_fraction", None)          # an analytic map has no vertices
        opts.pop("creases", None)                  # nor edges
        S, rep = fit_shape(shape, progress=not args.quiet, **opts)
        row["vertices"] = "-"
    else:
        V, F, shape = case_mesh(case, args.shared)
        check(V, F)
        Vs, _ = spherical_embedding(V, F, verbose=False)
        row["embedding_s"] = time.perf_counter() - t0
        S, rep = fit_mesh(V, F, Vs=Vs, check=False, progress=not args.quiet, **opts)
        row["vertices"] = len(V)
        fid = mesh_fidelity(S, V, F, Vs=Vs)
        if fid:
            row.update(fid)
    row["total_s"] = time.perf_counter() - t0
    row["fit_s"], row["steps"] = rep.seconds, rep.steps
    row["rough"] = curvature_roughness(S)
    row["scale"] = rep.options["input_scale"]
    row["heldout_pos"], row["heldout_nrm"] = rep.position_relative, rep.normal_mean_deg
    if shape is not None:
        row.update({f"exact_{k}": v for k, v in analytic_errors(S, shape).items()})
        if case in SHAPES:
            row.update({f"same_{k}": v for k, v in analytic_errors(S, shape, at="same").items()})
        if case not in SHAPES:       # a mesh of a radial shape: its vertices' own directions
            P = V / np.linalg.norm(V, axis=1, keepdims=True)
            base = libigl_errors(shape, V, F, P)
            if base:
                row.update({f"libigl_{k}": v for k, v in base.items()})
            # the fit where libigl is scored: at the surface points nearest the vertices
            row.update({f"vtx_{k}": v for k, v in analytic_errors(
                S, shape, p=nearest_parameters(S, V)).items()})
    if case in CAD:
        row.update(cad_errors(S, case, V, F))
    if case == "ellipsoid":
        from sns_np.demo import ellipsoid_foot_point, ellipsoid_geometry
        dq = differential_quantities(S, uniform_sphere(20000, rng=2024))
        n_ref, H_ref, K_ref = ellipsoid_geometry(ellipsoid_foot_point(dq.x))
        row["exact_nrm"] = float(np.degrees(np.arccos(np.clip(
            np.einsum("ij,ij->i", dq.n, n_ref), -1, 1))).mean())
        row["exact_H"] = float(np.abs(dq.H - H_ref).mean() / np.abs(H_ref).mean())
        row["exact_K"] = float(np.abs(dq.K - K_ref).mean() / np.abs(K_ref).mean())
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        name = os.path.splitext(os.path.basename(case))[0] if _is_mesh_file(case) else case
        S.save(os.path.join(args.out, f"{name}.npz"))
    return row


COLUMNS = [("case", "{}"), ("vertices", "{}"), ("total_s", "{:.0f}"), ("steps", "{}"),
           ("scale", "{:g}"), ("dist", "{:.2e}"), ("nrm", "{:.2f}"), ("dense_m2s", "{:.2e}"),
           ("heldout_pos", "{:.2e}"), ("heldout_nrm", "{:.2f}"), ("rough", "{:.3f}"),
           ("exact_nrm", "{:.3f}"),
           ("exact_H", "{:.2%}"), ("exact_K", "{:.2%}"), ("same_nrm", "{:.3f}"),
           ("same_H", "{:.2%}"), ("same_K", "{:.2%}"), ("vtx_nrm", "{:.3f}"),
           ("vtx_H", "{:.2%}"), ("vtx_K", "{:.2%}"), ("flat_H", "{:.4f}"),
           ("libigl_nrm", "{:.2f}"), ("libigl_H", "{:.1%}"), ("libigl_K", "{:.1%}")]


def print_row(row, header=False):
    if header:
        print(" | ".join(name for name, _ in COLUMNS))
    print(" | ".join(fmt.format(row[name]) if name in row else "" for name, fmt in COLUMNS),
          flush=True)


def comparison_case(args):
    from sns_np.shapes import Ellipsoid
    shape = Ellipsoid(1.0, 1.3, 0.7)
    opts = fit_options(args)
    variants = ({"dtype": "float32"}, {"dtype": "float64"}) if args.cases[0] == "dtype" else \
        ({"init": "ridge"}, {"init": "random"})
    opts.setdefault("steps", 600)
    print(f"Ellipsoid(1, 1.3, 0.7), fit_shape, {opts}")
    for v in variants:
        S, rep = fit_shape(shape, progress=not args.quiet, **{**opts, **v})
        e = analytic_errors(S, shape)
        print(f"  {v}: {rep.steps} steps in {rep.seconds:.1f} s "
              f"({rep.seconds / rep.steps * 1e3:.0f} ms/step); normal error {e['nrm']:.3f} deg, "
              f"H error {100 * e['H']:.2f}%, position RMS {rep.position_rms:.2e}")


def exact_normal_floor(shape, V, F, n=20000):
    """How far from the exact shape's normals (closest point, more than POLE from the poles)
    are the mesh's interpolated normals and its Loop surface's (two levels), at points uniform
    by area: what a surface that follows the mesh, or a classical smoothing of it, knows."""
    import igl
    out = {}
    F = np.asarray(F, np.int64)
    for label, (VV, FF) in (("mesh", (V, F)), ("loop", igl.loop(V, F, 2))):
        f, b = sample_surface(VV, FF, n, rng=5)
        N = vertex_normals(VV, FF, weighting="angle")
        X = np.einsum("kc,kci->ki", b, VV[FF[f]])
        nx = np.einsum("kc,kci->ki", b, N[FF[f]])
        nx /= np.linalg.norm(nx, axis=1, keepdims=True)
        p = _project(shape, X, X / np.linalg.norm(X, axis=1, keepdims=True), iters=6)
        m = _off_poles(p)
        nt = differential_quantities(shape, p).n
        out[label] = float(np.degrees(np.arccos(np.clip(
            np.einsum("ij,ij->i", nx, nt), -1, 1)))[m].mean())
    return out


def loop_case(args):
    """What a Loop subdivision surface of each mesh case reaches on the same measures; for
    the meshes of the paper's shapes, how far its normals and the mesh's are from the exact
    ones."""
    names = args.cases[1:] or list(MESHES)
    bad = [c for c in names if c not in MESHES and c not in ANALYTIC_MESHES
           and not _is_mesh_file(c)]
    if bad:
        raise SystemExit(f"fit_quality.py loop: unknown mesh case(s) {bad}; expected some of "
                         f"{', '.join(list(MESHES) + list(ANALYTIC_MESHES))}, or the path of "
                         f"a mesh file")
    for case in names:
        V, F, shape = case_mesh(case, args.shared)
        if case in ANALYTIC_MESHES:
            r = exact_normal_floor(shape, V, F)
            print(f"{case}: normals at the closest point of the exact shape: the mesh's "
                  f"interpolated {r['mesh']:.2f} deg, its Loop surface {r['loop']:.2f} deg",
                  flush=True)
            continue
        r = loop_reference(V, F)
        print(f"{case}: Loop subdivision (2 levels): dist {r['dist']:.2e}, nrm "
              f"{r['nrm']:.2f} deg (median {r['nrm_median']:.2f})", flush=True)
        surfaces, F2 = normal_following(V, F, ties=TIES)
        for tie, V2 in zip(TIES, surfaces):
            r = refined_reference(V, F, V2, F2)
            print(f"{case}: following the normals (3 levels, tie {tie:g}): dist "
                  f"{r['dist']:.2e}, nrm {r['nrm']:.2f} deg (median {r['nrm_median']:.2f})",
                  flush=True)


def cad_errors(S, case, V, F, n=100_000, margin=0.1):
    """A CAD-like case's normal error (degrees) and mean |H - H_true| away from its edges
    (more than ``margin``), H times the radius of the sphere of the mesh's area, so that
    it reads against a sphere's 1."""
    dq = differential_quantities(S, uniform_sphere(n, rng=8), on_degenerate="nan")
    m, n_true, H_true = exact_away_from_edges(case, dq.x, margin)
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", dq.n, n_true), -1, 1)))
    r = np.sqrt(face_areas(V, F).sum() / (4 * np.pi))
    return {"exact_nrm": float(np.nanmean(ang[m])),
            "flat_H": float(np.nanmean(np.abs(dq.H - H_true)[m]) * r)}


def curvature_roughness(S, n=40000, eps=1e-3):
    """Mean ``|H(p) - H(p')|`` over ``n`` pairs of sphere points ``eps`` rad apart (random
    tangent direction), relative to the mean ``|H|``."""
    p = uniform_sphere(n, rng=3)
    R = tangent_frame(p)
    a = np.random.default_rng(4).random(n) * 2 * np.pi
    q = p + eps * (R[:, :, 0] * np.cos(a)[:, None] + R[:, :, 1] * np.sin(a)[:, None])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    H1, H2 = differential_quantities(S, p).H, differential_quantities(S, q).H
    return float(np.abs(H1 - H2).mean() / np.abs(H1).mean())


def parameter_drift(S, shape, n=20000):
    """Where a ``fit_shape`` fit's points are, away from the poles: the mean distance to the
    exact point of the same sphere point, its normal and tangential parts, and the mean
    difference of the exact H between the closest point and the same point (relative to
    the mean |H|)."""
    p = uniform_sphere(n, rng=11)
    x = S(p)
    dT = differential_quantities(shape, p)
    e = x - dT.x
    en = np.einsum("ij,ij->i", e, dT.n)
    m = _off_poles(p)
    pc = _project(shape, x, x / np.linalg.norm(x, axis=1, keepdims=True), iters=6)
    Hc = differential_quantities(shape, pc).H
    return {"drift": float(np.linalg.norm(e, axis=1)[m].mean()),
            "normal": float(np.abs(en)[m].mean()),
            "tangential": float(np.linalg.norm(e - en[:, None] * dT.n, axis=1)[m].mean()),
            "H_moved": float(np.abs(Hc - dT.H)[m].mean() / np.abs(dT.H[m]).mean())}


def models_case(args):
    """Saved models: the roughness of their mean curvature; for ``SHAPE=PATH``, the drift."""
    from sns_np import SphericalNeuralSurface
    if len(args.cases) < 2:
        sys.exit("models needs one or more saved models: PATH or SHAPE=PATH")
    for spec in args.cases[1:]:
        name, _, path = spec.rpartition("=")
        if name and name not in SHAPES:
            sys.exit(f"unknown shape {name!r} in {spec!r}; expected one of {', '.join(SHAPES)}")
        S = SphericalNeuralSurface.load(path)
        line = f"{path}: H roughness {curvature_roughness(S):.3f}"
        if name:
            d = parameter_drift(S, _shape(name))
            line += (f"; {name}: drift {d['drift']:.2e} (normal {d['normal']:.2e}, tangential "
                     f"{d['tangential']:.2e}), exact H moved by it {d['H_moved']:.2%}")
        print(line, flush=True)


def detail_case(args):
    """The detail measures that choose the fitting defaults, for every case: the read-out
    errors of the positions and of the unit normals; for a mesh, its curvature jitter too
    (the input of the fine-sample rule, sns_np.surface._targets.smooth_sampling)."""
    from sns_np.surface.fit import _MeshTarget, _ShapeTarget, readout_errors
    for case in ALL:
        if case in SHAPES:
            target, n = _ShapeTarget(_shape(case)), "-"
        else:
            V, F, _ = case_mesh(case, args.shared)
            target, n = _MeshTarget(V, F, verbose=False), len(V)
        d, dn = readout_errors(target)
        jitter = "" if case in SHAPES else f", curvature jitter {curvature_jitter(V, F):.3f}"
        print(f"{case}: {n} vertices, detail {d:.2e}, normals {dn:.2e}{jitter}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", default=list(ALL),
                    help=f"cases among {', '.join(ALL)}, or dtype / init / detail, or loop "
                         f"followed by mesh cases, or models followed by saved models "
                         f"(default: all)")
    for name, typ in (("width", int), ("depth", int), ("steps", int), ("batch", int),
                      ("seed", int),
                      ("lr", float), ("lr-min", float), ("time-budget", float),
                      ("input-scale", float), ("normal-weight", float),
                      ("vertex-fraction", float), ("jacobian-weight", float),
                      ("hessian-weight", float), ("tangent-weight", float),
                      ("closest-after", float), ("anchor-weight", float),
                      ("closest-normal-weight", float), ("second-moment-decay", float),
                      ("normal-huber", float), ("area-weight-max", float)):
        ap.add_argument(f"--{name}", type=typ)
    ap.add_argument("--dtype", choices=["float32", "float64"])
    ap.add_argument("--smooth", choices=MESH_SMOOTHING)
    ap.add_argument("--creases", type=lambda t: check_creases(
                        t if t in ("auto", "none") else float(t)),
                    help="auto, none or an angle in degrees (fit_mesh's creases)")
    ap.add_argument("--sampling", choices=["area", "error"])
    ap.add_argument("--optimizer", choices=["adam", "rmsprop", "sgd", "soap"])
    ap.add_argument("--out", help="folder for the fitted models")
    ap.add_argument("--shared", default=SHARED, help="folder of the shared meshes")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    if args.cases and args.cases[0] in ("dtype", "init"):
        comparison_case(args)
        return
    if args.cases and args.cases[0] == "detail":
        detail_case(args)
        return
    if args.cases and args.cases[0] == "loop":
        loop_case(args)
        return
    if args.cases and args.cases[0] == "models":
        models_case(args)
        return
    bad = [c for c in args.cases if c not in ALL and not _is_mesh_file(c)]
    if bad:
        ap.error(f"unknown case(s) {bad}; expected some of {', '.join(ALL)}, or the path of "
                 f"a mesh file")
    print(f"options: {fit_options(args) or 'defaults'}")
    for i, case in enumerate(args.cases):
        print_row(run_case(case, args), header=i == 0)


if __name__ == "__main__":
    main()
