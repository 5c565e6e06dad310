"""Bijective spherical embedding of a genus-0 mesh.

Pipeline (:func:`spherical_embedding`):

1. **Conformalized mean curvature flow** (Kazhdan, Solomon & Ben-Chen 2012). The mesh is
   normalised to unit area; each implicit step solves ``(M_t - tau L_0) X_{t+1} = M_t X_t``
   with the cotangent stiffness ``L_0`` of the *input* mesh (fixed: that is what makes the flow
   conformal and non-singular) and the lumped mass ``M_t`` of the current surface; the result is
   recentred and rescaled to unit area. The flow stops once the surface is round
   (relative std of ``|X_i|`` below ``round_tol``) and fold-free after central projection, or
   when that deviation stops decreasing.
2. **Central projection** ``p_i = X_i / |X_i|``.
3. **Möbius centring** (:func:`mobius_centre`): the Möbius transformation of the sphere that
   moves the centre of mass of the pushed-forward surface area (vertex masses of the input
   mesh) to the origin. This fixes the Möbius freedom left by the conformal flow and spreads
   the area as evenly as a conformal map can (Baden, Crane & Kazhdan 2018).
4. **Fold repair** (:class:`~sns_np.mesh.foldrepair.FoldRepair`): vertices of folded triangles
   are moved into the kernel of their 1-ring (a small linear programme in the gnomonic chart),
   and regions that still fold are re-embedded by Tutte's method with mean-value weights.
   Where folds remain, the embedding starts over from Tutte's method on the whole sphere
   (:func:`~sns_np.mesh.foldrepair.tutte_sphere`) and, where a long thin part (a blade)
   makes that collapse too, from Tutte maps of two halves cut along the part
   (:func:`~sns_np.mesh.foldrepair.tutte_halves`).
5. **Area balancing** (``balance``): a conformal map squeezes protrusions exponentially (the
   armadillo's fingers get ``e^-27`` of their fair share of the sphere). Stretch-energy
   minimisation (:func:`~sns_np.mesh.stretch.minimise_stretch`, Yueh et al. 2019) moves the
   map towards an equiareal one by reweighted Tutte solves in stereographic charts, and a
   density-equalising flow (:func:`~sns_np.mesh.equalise.equalise_areas`, Gastner & Newman
   2004 on the sphere) evens out what is left at the scale of a fixed grid. Both keep the map
   fold-free. The stretch minimisation runs twice, accepting detours of its spread up to
   1.1 and up to 1.5 times the best (``STRETCH_TOLERANCES``); the patient run replaces the
   strict one where it is clearly better (``PATIENT_GAIN``): the strict run stalls on long
   thin limbs (a horse's legs), the patient one overshoots on others (the armadillo). By
   default the candidate (conformal, stretch, stretch + density) with the
   smallest 99th-percentile stretch of the sphere-to-surface map is returned; where the
   density flow ends worse than the stretch minimisation it started from (a part squeezed into
   less than one cell of its grid), the flow is also run in partial passes
   (``STAGED_STRENGTH``), a fourth candidate. Where no candidate reaches a stretch p99 of
   ``HALVES_GATE``, the same balancing also starts from
   :func:`~sns_np.mesh.foldrepair.tutte_halves`, which cuts long thin parts along their
   length instead of squeezing them (candidates ``"halves"``, ``"halves+stretch"``, ...).

References
----------
M. Kazhdan, J. Solomon and M. Ben-Chen, "Can mean-curvature flow be modified to be
non-singular?", Computer Graphics Forum 31(5) (SGP), 2012.

A. Baden, K. Crane and M. Kazhdan, "Möbius registration", Computer Graphics Forum 37(5) (SGP),
2018.

M.-H. Yueh, W.-W. Lin, C.-T. Wu and S.-T. Yau, "A novel stretch energy minimization algorithm
for equiareal parameterizations", Journal of Scientific Computing 78, 2019.

M. T. Gastner and M. E. J. Newman, "Diffusion-based method for producing density-equalizing
maps", PNAS 101(20), 2004.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from .._validation import as_points, check_choice, check_positive_float, check_positive_int
from ._arrays import as_mesh
from .check import check
from .equalise import equalise_areas
from .errors import EmbeddingError
from .foldrepair import FoldRepair, tutte_halves, tutte_sphere
from .operators import cotan_laplacian, face_areas, mass_matrix
from .spherical import (
    area_distortion,
    face_stretch,
    orientation_determinants,
    spherical_triangle_areas,
)
from .stretch import minimise_stretch

__all__ = ["EmbeddingReport", "spherical_embedding", "mobius_centre"]


@dataclass(frozen=True)
class EmbeddingReport:
    """Diagnostics of :func:`spherical_embedding`.

    Attributes
    ----------
    method : str
        The returned candidate: ``"conformal"``, ``"stretch"``, ``"density"`` or
        ``"staged"`` (the density flow in partial passes, computed by ``balance="auto"`` only
        where the full flow ends worse than the stretch minimisation) (or
        ``"tutte"`` when the conformal map could not be repaired and the Tutte fallback of
        :func:`~sns_np.mesh.foldrepair.tutte_sphere` was balanced instead, and ``"halves"``
        when that folded too and :func:`~sns_np.mesh.foldrepair.tutte_halves` was), or one
        of the same balanced from ``tutte_halves`` (``"halves"``, ``"halves+stretch"``,
        ``"halves+density"``, ``"halves+staged"``) where ``balance="auto"`` found no
        candidate below a stretch p99 of ``HALVES_GATE``.
    flow_steps : int
        Conformalized mean curvature flow steps taken.
    roundness : float
        Relative standard deviation of ``|X_i|`` of the flowed surface (0 for a round sphere).
    folds_after_flow, folds_after_centring, folds_after_repair : int
        Triangles with ``det[a, b, c] <= 0`` after projection, after Möbius centring and at the
        end (always 0 when the function returns).
    repair_rounds, repaired_vertices : int
        Rounds of Tutte region repair of the conformal map and the vertices the repair moved.
    centring_iterations : int
    stretch_iterations, density_steps : int
        Accepted stretch-minimisation steps and density-flow steps of the returned candidate
        (0 when not run; for ``"staged"`` the steps of the passes kept).
    conformal_log_area_ratio_std, conformal_log_area_ratio_min : float
        Area distortion of the conformal map (of the Tutte fallback, when used).
    log_area_ratio_mean, log_area_ratio_std, log_area_ratio_min, log_area_ratio_max : float
        Statistics over faces of ``log((s_f / sum s) / (A_f / sum A))`` with ``s_f`` the
        spherical and ``A_f`` the surface triangle area (0 everywhere for an area-preserving map).
    stretch_p99, stretch_max : float
        99th percentile (weighted by surface area) and maximum over faces of the largest
        singular value of the sphere-to-surface map, both normalised to area ``4 pi``
        (:func:`sns_np.mesh.spherical.face_stretch`); the candidate with the smallest
        ``stretch_p99`` is returned.
    candidates : dict
        ``stretch_p99`` of every candidate computed.
    time : float
        Wall-clock seconds.

    Examples
    --------
    >>> from sns_np.mesh import spherical_embedding
    >>> from sns_np.shapes import Ellipsoid
    >>> V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    >>> Vs, report = spherical_embedding(V, F)
    >>> report.folds_after_repair, report.method in ("conformal", "stretch", "density", "staged",
    ...                                             "tutte", "halves")
    (0, True)
    """

    n_vertices: int
    n_faces: int
    method: str
    flow_steps: int
    roundness: float
    folds_after_flow: int
    folds_after_centring: int
    folds_after_repair: int
    repair_rounds: int
    repaired_vertices: int
    centring_iterations: int
    stretch_iterations: int
    density_steps: int
    conformal_log_area_ratio_std: float
    conformal_log_area_ratio_min: float
    log_area_ratio_mean: float
    log_area_ratio_std: float
    log_area_ratio_min: float
    log_area_ratio_max: float
    stretch_p99: float
    stretch_max: float
    candidates: dict
    time: float

    @property
    def flipped_before(self) -> int:
        """Folded triangles of the flow's projection, before any repair."""
        return self.folds_after_flow

    @property
    def flipped_after(self) -> int:
        """Folded triangles of the result (always 0)."""
        return self.folds_after_repair

    def __str__(self) -> str:
        return (f"{self.method} embedding: {self.flow_steps} flow steps, folds "
                f"{self.folds_after_flow} -> {self.folds_after_repair}, log area ratio std "
                f"{self.log_area_ratio_std:.2f} [{self.log_area_ratio_min:.2f}, "
                f"{self.log_area_ratio_max:.2f}] (conformal "
                f"{self.conformal_log_area_ratio_std:.2f}), stretch p99 "
                f"{self.stretch_p99:.2f}, {self.time:.1f} s")


def _mobius(P, a):
    d = P - a
    Q = (1.0 - a @ a) * d / np.einsum("ij,ij->i", d, d)[:, None] - a
    return Q / np.linalg.norm(Q, axis=1, keepdims=True)


def mobius_centre(Vs, weights, *, tol: float = 1e-10, max_iter: int = 500):
    """Möbius transformation of the sphere that moves the weighted centre of mass to the origin.

    Iterates ``p <- T_a(p)`` with ``a`` the current centre of mass ``sum w_i p_i / sum w_i``
    (damped so that ``|a| <= 0.9`` and the centre shrinks at every step), where
    ``T_a(x) = (1 - |a|^2)(x - a) / |x - a|^2 - a`` is the Möbius automorphism of the ball that
    sends ``a`` to the origin; on the sphere it spreads out the points near ``a / |a|``.

    Parameters
    ----------
    Vs : (n, 3) float array, unit vectors
    weights : (n,) float array, positive masses (e.g. the vertex areas of the surface)
    tol : float
        Stop when ``|centre| < tol``.
    max_iter : int

    Returns
    -------
    Vc : (n, 3) float array, unit vectors with centre of mass (nearly) 0
    iterations : int

    References
    ----------
    A. Baden, K. Crane and M. Kazhdan, "Möbius registration", Computer Graphics Forum 37(5),
    2018.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(2)
    >>> P = V + [0, 0, 0.5]; P /= np.linalg.norm(P, axis=1, keepdims=True)
    >>> Q, _ = mobius_centre(P, np.ones(len(P)))
    >>> float(np.linalg.norm(Q.mean(axis=0))) < 1e-9
    True
    """
    P = as_points(Vs, "Vs")
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (P.shape[0],) or not np.all(np.isfinite(w)) or not (w >= 0).all() \
            or not w.sum() > 0:
        raise ValueError(f"weights must be {P.shape[0]} finite non-negative masses with a "
                         f"positive sum, got shape {w.shape}")
    w = w / w.sum()
    c = w @ P
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (reported)
        nc = float(np.linalg.norm(c))
        if nc < tol:
            return P, it - 1
        g = 1.0
        while True:
            a = g * c
            na = np.linalg.norm(a)
            if na > 0.9:
                a = a * (0.9 / na)
            Q = _mobius(P, a)
            cq = w @ Q
            if np.linalg.norm(cq) < nc or g < 1e-6:
                break
            g *= 0.5
        P, c = Q, cq
    return P, it


def _cmcf(V, F, tau, max_steps, round_tol):
    """Conformalized MCF to a round shape; returns unit vectors, steps and roundness."""
    X = V - V.mean(axis=0)
    X = X / np.sqrt(face_areas(X, F).sum())
    L = cotan_laplacian(X, F)
    devs = []
    P = X / np.linalg.norm(X, axis=1, keepdims=True)
    step = 0
    for step in range(1, max_steps + 1):  # noqa: B007 (reported)
        M = mass_matrix(X, F, "barycentric")
        system = (M - tau * L).tocsc()
        # system is symmetric positive definite: a symmetric ordering without pivoting is exact
        # and ~50x faster than the default partial pivoting
        lu = spla.splu(system, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
        X = lu.solve(M @ X)
        if not np.all(np.isfinite(X)):
            raise EmbeddingError(f"conformalized mean curvature flow diverged at step {step}")
        m = M.diagonal()
        X -= (m @ X) / m.sum()
        X /= np.sqrt(face_areas(X, F).sum())
        r = np.linalg.norm(X, axis=1)
        dev = float(r.std() / r.mean())
        devs.append(dev)
        P = X / r[:, None]
        if dev < round_tol and not (orientation_determinants(P, F) <= 0).any():
            break
        if len(devs) > 10 and devs[-11] - dev < 0.01 * dev:
            break                                   # stagnated: the discrete flow is done
    return P, step, devs[-1] if devs else 0.0


def _stretch_p99(V, F, P, area):
    """Area-weighted 99th percentile of the per-face stretch."""
    sig = face_stretch(V, F, P)
    order = np.argsort(sig)
    cum = np.cumsum(area[order]) / area.sum()
    return float(sig[order][np.searchsorted(cum, 0.99)]), float(sig.max())


BALANCE = ("auto", "none", "stretch", "density")

#: the stretch minimisation's tolerances (how far above the best spread a step may go): a
#: strict run, and a patient one that replaces it only if its 99th-percentile stretch is
#: below ``PATIENT_GAIN`` times the strict run's. The strict run alone stalled on a horse
#: (48,485 vertices decimated to 20,000: 4 accepted steps, stretch p99 233, its legs at e^-11
#: of their share of the sphere), where the patient one reaches 17.6; elsewhere the patient
#: run is worse (the armadillo: 22 against 8.5) or a few percent better while it turns the
#: map (a small ellipsoid: 1.24 against 1.32, rotated by 20 degrees), so a clear gain is asked
#: (docs/mesh.md)
STRETCH_TOLERANCES = (1.1, 1.5)
PATIENT_GAIN = 0.8

#: the density flow in partial passes, run only where the full flow ends with a larger
#: stretch than the stretch minimisation it started from: with a part squeezed into less
#: than one cell of the flow's grid, the full flow can collapse triangles (a screwdriver's
#: blade, 3,395 vertices: stretch p99 55.5 before the flow, 6.3e6 after it). Each pass
#: removes ``STAGED_STRENGTH`` of the log area distortion left, so the squeezed part grows
#: over the grid's cells pass by pass; a pass is kept while it lowers the
#: stretch p99 to below ``STAGED_GAIN`` times the best so far, at most ``STAGED_PASSES``
#: (the screwdriver: 55.5, then 19.1 and 11.0; a third pass gains 2%, a fourth collapses
#: triangles again; docs/mesh.md)
STAGED_STRENGTH = 0.4
STAGED_GAIN = 0.95
STAGED_PASSES = 6

#: where no candidate of the conformal (or Tutte) start reaches a stretch p99 of
#: ``HALVES_GATE``, "auto" also balances :func:`~sns_np.mesh.foldrepair.tutte_halves`, a start
#: in which long thin parts are cut along their length instead of squeezed (the
#: blade of a sword, 22,293 vertices: no fold-free map otherwise; docs/mesh.md)
HALVES_GATE = 8.0
#: ... and takes one of them only if its stretch p99 is below ``HALVES_GAIN`` times the best
#: of the others: at 0.66 and 0.68 of it (a screwdriver, a penguin) the default fits were
#: worse and level, as a Tutte start leaves the bulk of the surface more stretched (the
#: screwdriver's median stretch 1.96 against 1.31)
HALVES_GAIN = 0.5


def _staged_density(V, F, P, p99, area, grid_level, repair):
    """The density flow in partial passes from ``P`` (stretch p99 ``p99``;
    ``STAGED_STRENGTH`` each), kept while each pass lowers the stretch p99 below
    ``STAGED_GAIN`` times the best so far.
    Returns (the last kept map, the passes kept, their flow steps)."""
    best, X, kept, steps = p99, P, 0, 0
    for _ in range(STAGED_PASSES):
        Y, info = equalise_areas(V, F, X, strength=STAGED_STRENGTH, grid_level=grid_level,
                                 repair=repair)
        score = _stretch_p99(V, F, Y, area)[0]
        if not score < STAGED_GAIN * best:
            break
        best, X, kept, steps = score, Y, kept + 1, steps + info["steps"]
    return X, kept, steps


def _halves(V, F, repair, max_repair_rounds):
    """:func:`tutte_halves` with its folds repaired, or None if no fold-free one is found."""
    try:
        P = tutte_halves(V, F, repair.W)
    except EmbeddingError:
        return None
    if (orientation_determinants(P, F) <= 0).any():
        repair(P, max_repair_rounds)
    return None if (orientation_determinants(P, F) <= 0).any() else P


def _balanced(V, F, P, base, balance, area, repair, stretch_iterations, grid_level, say,
              prefix=""):
    """The candidates balanced from the fold-free start ``P`` (named ``base``): the start,
    its stretch minimisation and, for "auto" and "density", the density flow from that (and
    for "auto", where the full flow ends worse, its partial passes), names prefixed.
    Returns (maps, their (stretch p99, max), their (stretch iterations, density steps))."""
    candidates = {base: P}
    steps = {base: (0, 0)}
    if balance != "none":
        runs = []
        for tol in STRETCH_TOLERANCES:
            Ps, info = minimise_stretch(V, F, P, iterations=stretch_iterations,
                                        tolerance=tol, repair=repair)
            runs.append((_stretch_p99(V, F, Ps, area)[0], Ps, info["accepted"]))
            say(f"{prefix}stretch minimisation (tolerance {tol:g}): {info['accepted']} steps, "
                f"log area ratio std {info['spread']:.2f}, stretch p99 {runs[-1][0]:.2f}")
        # the first (strict) run unless a later one is clearly better
        best = runs[0]
        for run in runs[1:]:
            if run[0] < PATIENT_GAIN * best[0]:
                best = run
        p99_stretch, Ps, n_stretch = best
        candidates[prefix + "stretch"], steps[prefix + "stretch"] = Ps, (n_stretch, 0)
        if balance in ("auto", "density"):
            Pd, info = equalise_areas(V, F, Ps, grid_level=grid_level, repair=repair)
            candidates[prefix + "density"] = Pd
            steps[prefix + "density"] = (n_stretch, info["steps"])
            say(f"{prefix}density equalisation: {info['steps']} steps")
            if balance == "auto" and _stretch_p99(V, F, Pd, area)[0] >= p99_stretch:
                Pg, passes, n_staged = _staged_density(V, F, Ps, p99_stretch, area,
                                                       grid_level, repair)
                if passes:
                    candidates[prefix + "staged"] = Pg
                    steps[prefix + "staged"] = (n_stretch, n_staged)
                    say(f"{prefix}the full flow did not help: {passes} partial pass(es) of "
                        f"strength {STAGED_STRENGTH}, {n_staged} steps")
    scores = {k: _stretch_p99(V, F, X, area) for k, X in candidates.items()}
    return candidates, scores, steps


def spherical_embedding(V, F, *, balance: str = "auto", tau: float = 1e-2,
                        max_steps: int = 300, round_tol: float = 5e-3,
                        max_repair_rounds: int = 30, stretch_iterations: int = 80,
                        grid_level: int = 5, verbose: bool = False):
    """Map the vertices of a closed genus-0 mesh bijectively to the unit sphere.

    Conformalized mean curvature flow, central projection, Möbius centring of the surface area
    and repair of any folds give a conformal embedding; area balancing then moves it towards an
    equiareal one (see the module docstring). The result is fold-free: every spherical triangle
    has ``det[a, b, c] > 0`` and the geodesic triangles tile the sphere exactly once.

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, a mesh that passes :func:`sns_np.mesh.check`
    balance : {"auto", "none", "stretch", "density"}
        ``"none"``: the conformal map. ``"stretch"``: followed by stretch-energy minimisation
        (:func:`~sns_np.mesh.stretch.minimise_stretch`). ``"density"``: followed by that and a
        density-equalising flow (:func:`~sns_np.mesh.equalise.equalise_areas`). ``"auto"``:
        compute all three and return the one with the smallest 99th-percentile stretch
        (largest singular value of the sphere-to-surface map, area-weighted), the quantity that
        limits how well a network on the sphere can fit the surface; where the density flow
        ends worse than the stretch minimisation, its partial passes are a fourth candidate
        (``"staged"``, module docstring); where no candidate reaches a stretch p99 of
        ``HALVES_GATE``, the same candidates balanced from
        :func:`~sns_np.mesh.foldrepair.tutte_halves` too (``"halves+density"`` etc.).
    tau : float
        Time step of the flow, relative to the mesh normalised to unit area.
    max_steps : int
        Upper bound on flow steps (the flow usually stops after 10-60).
    round_tol : float
        The flow stops once the relative std of ``|X_i|`` is below this and the projection has
        no folds.
    max_repair_rounds : int
        Rounds of Tutte region repair; round ``k`` grows the folded triangles by ``k + 1``
        rings.
    stretch_iterations : int
        Weight updates of the stretch minimisation.
    grid_level : int
        Icosphere level of the density grid of the density-equalising flow.
    verbose : bool
        Print one line per stage to stderr.

    Returns
    -------
    Vs : (n, 3) float array, unit vectors
    report : EmbeddingReport

    Raises
    ------
    MeshDefectError
        The input fails :func:`sns_np.mesh.check`.
    EmbeddingError
        The flow diverged or the repair could not remove every fold.

    References
    ----------
    M. Kazhdan, J. Solomon and M. Ben-Chen, "Can mean-curvature flow be modified to be
    non-singular?", Computer Graphics Forum 31(5), 2012.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> Vs, report = spherical_embedding(V * [1.0, 2.0, 3.0], F, balance="stretch")
    >>> report.folds_after_repair, Vs.shape
    (0, (642, 3))
    """
    t0 = time.perf_counter()
    V, F = as_mesh(V, F)
    check(V, F)
    check_choice(balance, "balance", BALANCE)
    tau = check_positive_float(tau, "tau")
    max_steps = check_positive_int(max_steps, "max_steps")
    round_tol = check_positive_float(round_tol, "round_tol")
    max_repair_rounds = check_positive_int(max_repair_rounds, "max_repair_rounds", minimum=0)
    stretch_iterations = check_positive_int(stretch_iterations, "stretch_iterations", minimum=0)
    grid_level = check_positive_int(grid_level, "grid_level", minimum=1)

    def say(msg):
        if verbose:
            print(f"spherical_embedding: {msg} ({time.perf_counter() - t0:.1f} s)",
                  file=sys.stderr, flush=True)

    P, steps, roundness = _cmcf(V, F, tau, max_steps, round_tol)
    folds_flow = int((orientation_determinants(P, F) <= 0).sum())
    say(f"conformalized MCF: {steps} steps, roundness {roundness:.1e}, {folds_flow} folds")
    P, it_centre = mobius_centre(P, mass_matrix(V, F, "barycentric").diagonal())
    folds_centre = int((orientation_determinants(P, F) <= 0).sum())
    rounds, n_moved = 0, 0
    repair = FoldRepair(V, F)
    if folds_centre:
        rounds, n_moved = repair(P, max_repair_rounds)
        say(f"fold repair: {folds_centre} folds, {n_moved} vertices moved")
    folds_end = int((orientation_determinants(P, F) <= 0).sum())
    base = "conformal"
    if folds_end:
        # coarse or spiky meshes (negative cotangents) can fold beyond local repair: start
        # instead from a Tutte embedding, fold-free by construction, and let balancing fix it
        say(f"{folds_end} folds left after repair; falling back to a Tutte embedding")
        P, base = tutte_sphere(V, F, repair.W), "tutte"
        folds_end = int((orientation_determinants(P, F) <= 0).sum())
        if folds_end:
            # a long thin part telescoped beyond float64 (a blade, a limb): Tutte maps of
            # two halves cut along the parts' length instead
            say(f"{folds_end} folds in the Tutte embedding; trying two halves")
            Ph = _halves(V, F, repair, max_repair_rounds)
            if Ph is not None:
                P, base, folds_end = Ph, "halves", 0
        if folds_end:
            raise EmbeddingError(
                f"spherical embedding still has {folds_end} folded triangle(s) after "
                f"{max_repair_rounds} repair rounds and the Tutte fallback (flow: "
                f"{folds_flow}, after centring: {folds_centre})")
    area = face_areas(V, F)
    d_conf = area_distortion(V, F, P)
    candidates, scores, steps_of = _balanced(V, F, P, base, balance, area, repair,
                                             stretch_iterations, grid_level, say)
    gated = set()
    if (balance == "auto" and base != "halves"
            and min(score[0] for score in scores.values()) > HALVES_GATE):
        # long thin parts squeezed beyond what balancing recovers: the halves' route too
        say(f"stretch p99 above {HALVES_GATE:g}: balancing two halves too")
        Ph = _halves(V, F, repair, max_repair_rounds)
        if Ph is not None:
            more = _balanced(V, F, Ph, "halves", balance, area, repair, stretch_iterations,
                             grid_level, say, prefix="halves+")
            for mine, theirs in zip((candidates, scores, steps_of), more):
                mine.update(theirs)
            gated = set(more[0])
    if balance == "auto":
        method = min(scores.keys() - gated, key=lambda k: scores[k][0])
        if gated:
            # the halves' maps stretch the bulk of the surface more (a Tutte start is far
            # from conformal), so they replace the others only with a clearly smaller tail
            best = min(gated, key=lambda k: scores[k][0])
            if scores[best][0] < HALVES_GAIN * scores[method][0]:
                method = best
    else:
        method = {"none": base}.get(balance, balance)
    n_stretch, n_density = steps_of[method]
    P = candidates[method]
    total = spherical_triangle_areas(P, F).sum()
    if (orientation_determinants(P, F) <= 0).any() or not abs(total - 4 * np.pi) < 1e-6:
        raise EmbeddingError(
            f"the spherical triangles cover an area of {total:.6g} instead of 4 pi = "
            f"{4 * np.pi:.6g}: the embedding is not one-to-one")
    d = area_distortion(V, F, P)
    say(f"chose the {method} candidate (stretch p99 {scores[method][0]:.2f})")
    return P, EmbeddingReport(
        n_vertices=V.shape[0], n_faces=F.shape[0], method=method, flow_steps=steps,
        roundness=roundness, folds_after_flow=folds_flow, folds_after_centring=folds_centre,
        folds_after_repair=folds_end, repair_rounds=rounds, repaired_vertices=n_moved,
        centring_iterations=it_centre, stretch_iterations=n_stretch, density_steps=n_density,
        conformal_log_area_ratio_std=float(d_conf.std()),
        conformal_log_area_ratio_min=float(d_conf.min()),
        log_area_ratio_mean=float(d.mean()), log_area_ratio_std=float(d.std()),
        log_area_ratio_min=float(d.min()), log_area_ratio_max=float(d.max()),
        stretch_p99=scores[method][0], stretch_max=scores[method][1],
        candidates={k: v[0] for k, v in scores.items()}, time=time.perf_counter() - t0)
