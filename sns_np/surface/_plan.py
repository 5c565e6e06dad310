"""What a fit left to "auto" becomes: the target's detail, the choices made from it, the
step-time probe and the learning-rate schedules (on the step count or on the clock)."""

from __future__ import annotations

import time

import numpy as np

from ..geometry import tangent_frame
from ..nn.mlp import ResidualMLP
from ..nn.optim import Schedule
from ..options import (
    AREA_WEIGHT_MAX,
    AUTO,
    AUTO_EXACT,
    CLOSEST_NORMAL_AREA,
    CLOSEST_NORMAL_MAX,
    COARSE_CLOSEST_NORMAL,
    COARSE_VERTEX_FRACTION,
    DETAIL_RANGE,
    EXACT_INPUT_SCALE_MAX,
    HESSIAN_WEIGHT,
    JACOBIAN_WEIGHT,
    LR_MIN,
    NORMAL_DETAIL_RANGE,
    NORMAL_HUBER,
    NORMAL_WEIGHT,
    RIPPLED_INPUT_SCALE,
    SAMPLE_TANGENT_WEIGHT,
    SAMPLE_VERTEX_FRACTION,
    SECOND_MOMENT_DECAY,
)
from ..sampling import uniform_sphere

#: the most steps a fit with no step count takes (it normally stops on its time budget)
_MAX_AUTO_STEPS = 1_000_000


class _ClockCosine:
    """A cosine schedule on the clock: the warm-up of ``base`` over its first steps, then the
    decay from ``lr`` to ``lr_min`` over the fraction of ``budget`` seconds elapsed."""

    kind = "cosine-clock"

    def __init__(self, base, clock, budget):
        self.base, self.clock, self.budget = base, clock, float(budget)

    def __call__(self, t):
        b = self.base
        lr = b.cosine_at(min(self.clock() / self.budget, 1.0))
        if b.warmup and t < b.warmup:
            lr *= (t + 1) / b.warmup
        return float(lr)


_OPTIMIZER_WHY = {
    "adam": ": Adam (a smooth target needs no more)",
    "soap": ": SOAP, Adam in the eigenbasis of Shampoo's factors for the hidden matrices "
            "(detail is learnt in fewer steps, docs/fitting.md)"}

#: what AUTO_EXACT's choices are, for the reasons recorded
_EXACT_WHAT = {"width": "network", "depth": "network",
               "time_budget": "budget (its curvature keeps improving with time, "
                              "docs/fitting.md)"}

_SAMPLING_WHY = {
    "area": ": uniform by area (the error is spread evenly)",
    "error": ": more samples where the recent error is, weighted back to the same loss"}


def _closest_why(v):
    if v >= 1.0:
        return ": the embedding's correspondence throughout (a smooth mesh needs no more)"
    return (f": the embedding's correspondence for the first {v:.0%} of the fit, then the "
            f"nearest mesh points (the surface need not follow the embedding's piecewise-"
            f"linear parametrisation, docs/fitting.md)")


def _position(d, ends):
    """Where ``d`` lies between ``ends`` on a log scale, clipped to 0 - 1."""
    lo, hi = ends
    if d <= lo:
        return 0.0
    return float(min(np.log(d / lo) / np.log(hi / lo), 1.0))


def _auto_values(d, param="embedding", dn=None):
    """The interpolated choices for detail ``d`` (and the normals' read-out error ``dn``), and
    the position between the ends (0 - 1): the larger of ``d``'s in DETAIL_RANGE and ``dn``'s
    in NORMAL_DETAIL_RANGE. ``param`` "exact" (an analytic map) takes its detailed end's
    network from AUTO_EXACT."""
    t = _position(d, DETAIL_RANGE)
    if dn is not None:
        t = max(t, _position(dn, NORMAL_DETAIL_RANGE))
    a, b = AUTO["smooth"], AUTO["detailed"]
    if param == "exact":
        b = {**b, **AUTO_EXACT}
    # numbers on a log scale; a choice among names (sampling) from the nearer end
    vals = {k: (a[k] if t < 0.5 else b[k]) if isinstance(a[k], str)
            else float(a[k] ** (1 - t) * b[k] ** t) for k in a}
    if t in (0.0, 1.0):
        vals = dict(a if t == 0.0 else b)
    if param == "exact":
        vals["input_scale"] = min(vals["input_scale"], EXACT_INPUT_SCALE_MAX)
    return vals, t


def detail(target, width=256, depth=8, n=4096, seed=12345):
    """How much detail a target has: the held-out RMS error (normalised units) of the best
    linear read-out of the scale-4 features of a fresh reference network (256 x 8, whatever
    the network being fitted).

    Smooth shapes are nearly linear in those features (the built-in ellipsoid: 3.5e-3); meshes
    with ears, horns and faces are not (spot: 4.8e-2). It costs one forward pass of ``n``
    points and a ``width x width`` solve, and draws from its own generator, so it does not
    change a fit's random stream. A fit also weighs the same read-out's error on the unit
    normals (:func:`readout_errors`), which a low relief of short wavelength cannot hide.

    Examples
    --------
    >>> from sns_np.shapes import Bobble, Ellipsoid
    >>> from sns_np.surface._targets import _ShapeTarget
    >>> smooth = detail(_ShapeTarget(Ellipsoid(1.0, 1.3, 0.7)))
    >>> bumpy = detail(_ShapeTarget(Bobble()))
    >>> bool(smooth < DETAIL_RANGE[0]), bool(bumpy > DETAIL_RANGE[1])
    (True, True)
    """
    return readout_errors(target, width, depth, n, seed)[0]


def readout_errors(target, width=256, depth=8, n=4096, seed=12345):
    """The held-out RMS errors of the best linear read-out of a fresh reference network's
    scale-4 features: of the positions (:func:`detail`, normalised units) and of the unit
    normals (dimensionless), from one forward pass and one solve with both right-hand sides.

    A position error grows with the relief's height, a normal error with its slope: FLOWER
    with 3% of its relief has position error 1.0e-2 (between the ends of DETAIL_RANGE)
    and normal error 0.35 (detailed), the built-in ellipsoid's mesh 3.3e-3 and 6.9e-3.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> from sns_np.surface._targets import _ShapeTarget
    >>> pos, nrm = readout_errors(_ShapeTarget(Ellipsoid(1.0, 1.3, 0.7)))
    >>> bool(pos < DETAIL_RANGE[0]), bool(nrm < NORMAL_DETAIL_RANGE[0])
    (True, True)
    """
    g = np.random.default_rng(seed)
    net = ResidualMLP(width=width, depth=depth, seed=g, input_scale=4.0)
    p, q, nt = target.sample(2 * n, g)
    n = len(p) // 2                      # a target with a finite pool may return fewer
    if n < 16:
        raise ValueError(f"detail: the target returned {len(p)} samples; need at least 32")
    feats = net.features(p)
    G = feats[:n].T @ feats[:n]
    G[np.diag_indices_from(G)] += 1e-6 * np.trace(G) / G.shape[0]
    W = np.linalg.solve(G, feats[:n].T @ np.hstack([q[:n], nt[:n]]))
    r = feats[n:2 * n] @ W - np.hstack([q[n:2 * n], nt[n:2 * n]])
    return (float(np.sqrt((r[:, :3] ** 2).sum(axis=1).mean())),
            float(np.sqrt((r[:, 3:] ** 2).sum(axis=1).mean())))


#: the error for a derivative weight (Jacobian, Hessian) on a target without exact derivatives
NO_JACOBIAN = ("{}={:g} needs a target with exact derivatives along the sphere "
               "(fit_shape, an analytic map); a mesh's are those of its piecewise-linear "
               "spherical embedding, not data to match: use 0")

#: the options chosen by how the target is parametrised: their values and the reasons
BY_PARAMETRISATION = {
    "normal_weight": (NORMAL_WEIGHT, {
        "exact": "an exact parametrisation (an analytic map): the position term leads",
        "embedding": "a parametrisation through a spherical embedding: the normals steer the "
                     "fit past its tangential noise"}),
    "normal_huber": (NORMAL_HUBER, {
        "exact": "an exact parametrisation (an analytic map): the squared normal loss, as "
                 "measured",
        "embedding": "a mesh, judged by its mean angle: errors beyond this count by their "
                     "size, so a few large ones do not steer the fit"}),
    "lr_min": (LR_MIN, {
        "exact": "an exact parametrisation (an analytic map): the last steps at a lower rate "
                 "end nearer its exact targets",
        "embedding": "a parametrisation through a spherical embedding: the rate its figures "
                     "were measured with"}),
}

#: why SOAP's second-moment decay is what "auto" chooses (SECOND_MOMENT_DECAY)
_DECAY_WHY = {
    "exact": "SOAP on an analytic map: a long memory of the gradients' scale, which its "
             "curvature wants",
    "embedding": "SOAP on a mesh: a short memory follows the eigenbases as they turn, and "
                 "detail is learnt faster"}

#: the optimisers that take a second-moment decay (their ``betas[1]``)
WITH_SECOND_MOMENT = ("adam", "soap")


def area_weight_conflict(most, closest_after, normal_weight, nearest=True):
    """The error message when ``area_weight_max`` (``most``) is given but cannot act: it
    weights a mesh's nearest-point phase (``nearest``: the target has one) and needs the
    normals' derivatives; else None. ``closest_after`` and ``normal_weight`` may be None
    (auto)."""
    if not most:
        return None
    why = ("this target has no nearest-point phase (a mesh's, fit_mesh)" if not nearest
           else "closest_after=1 turns that phase off" if closest_after == 1.0
           else "normal_weight=0 computes no derivatives to measure the surface's area by"
           if normal_weight == 0.0 else None)
    if why is None:
        return None
    return (f"area_weight_max={most:g} weights the points of a mesh's nearest-point phase by "
            f"the fitted surface's own area, but {why}: use 0")


def closest_normal_conflict(weight, closest_after, normal_weight):
    """The error message when ``closest_normal_weight`` (``weight``) is given above 0 for a
    nearest-point phase that may run while ``normal_weight`` is 0: the fit then computes no
    derivatives, so the phase has no normals to compare; else None. ``closest_after`` and
    ``normal_weight`` may be None (auto)."""
    if not weight or closest_after == 1.0 or normal_weight != 0.0:
        return None
    return (f"closest_normal_weight={weight:g} weights the normal term of a mesh's "
            f"nearest-point phase, but normal_weight=0 computes no derivatives for it: use "
            f"closest_normal_weight=0, or a normal_weight above 0")


def option_conflict(o, nearest=True, phase=True):
    """The first contradiction among the options ``o`` (a mapping of option values, "auto"
    still None), or None: an optimiser's decay without a second moment, area weights that
    cannot act, a normal weight for a nearest-point phase without derivatives. ``nearest``:
    the target has nearest points; ``phase``: a nearest-point phase may run. Checked before
    any work (``fit._check_early``) and again once the automatic choices are made."""
    return (second_moment_conflict(o["optimizer"], o["second_moment_decay"])
            or area_weight_conflict(o["area_weight_max"], o["closest_after"],
                                    o["normal_weight"], nearest)
            or (closest_normal_conflict(o["closest_normal_weight"], o["closest_after"],
                                        o["normal_weight"]) if phase else None))


def second_moment_conflict(optimizer, decay):
    """The error message when ``decay`` (``second_moment_decay``) is given to an optimiser
    without a second moment, else None."""
    if decay is None or optimizer is None or optimizer in WITH_SECOND_MOMENT:
        return None
    return (f"second_moment_decay={decay:g} is the second-moment decay of "
            f"{' and '.join(WITH_SECOND_MOMENT)}; optimizer={optimizer!r} has none to set: "
            f"leave second_moment_decay unset or choose one of those")


#: the options of the losses on an analytic map's derivatives, and what they match
DERIVATIVE_WEIGHTS = {"jacobian_weight": (JACOBIAN_WEIGHT, "derivatives"),
                      "hessian_weight": (HESSIAN_WEIGHT, "second derivatives")}


def _coarse(target):
    """``(coarse, why)`` for a mesh (:func:`~sns_np.surface._targets.coarseness`), ``(False,
    None)`` for no mesh."""
    if not hasattr(target, "sample_vertices"):
        return False, None
    return target.coarse


def _smooth_sample(target, o, net, read_out):
    """``(kind, why)``: whether the fit takes the recipe of a mesh whose vertices sample a
    smooth surface (:func:`~sns_np.surface._targets.smooth_sampling`, ``kind`` "fine" or
    "rippled": positions only, its vertices leading; None: not); only for a fresh fit of a
    mesh whose normal weight is left to "auto" (why None otherwise: nothing chosen), and only
    for a detailed target (``read_out()``, the detail read-out, at least halfway to the
    detailed end): on a smooth one, fitted at a small scale in a short budget, the normals
    speed the fit (the demo's ellipsoid at 240 s: 0.227 deg / H 1.96% with them, 0.316 /
    2.58% without; docs/fitting.md). A rippled mesh declined here keeps the normal-following
    defaults but no creases: "auto" creases were decided with the embedding, before the
    read-out (:class:`~sns_np.surface._targets._MeshTarget`)."""
    if net is not None or not hasattr(target, "smooth_sample") or o["normal_weight"] is not None:
        return None, None
    kind, why = target.smooth_sample
    if kind is not None:
        d, dn = read_out()
        t = _auto_values(d, "embedding", dn)[1]
        if t < 0.5:
            return None, (f"{why}; but a smooth target (detail {t:.2f} of the way to the "
                          f"detailed end, below 0.5), fitted at a small scale in a short "
                          f"budget, where following its normals is faster")
    return kind, why


def _vertex_fraction(target, sample=False):
    """The share of each batch drawn at the vertices, and why: ``COARSE_VERTEX_FRACTION`` on a
    coarse mesh, ``SAMPLE_VERTEX_FRACTION`` on a mesh whose vertices sample a smooth surface
    (``sample``), 0 otherwise (why None: no mesh)."""
    coarse, kind = _coarse(target)
    if kind is None:
        return 0.0, None        # no vertices (an analytic map): nothing to choose
    if sample:
        return SAMPLE_VERTEX_FRACTION, ("its vertices sample a smooth surface: they are "
                                        "exact, the Phong points between them the data too")
    if coarse:
        return COARSE_VERTEX_FRACTION, (f"{kind}: between its vertices the targets are "
                                        f"interpolated, at them exact")
    return 0.0, f"{kind}: its faces only"


def _area_weights_off(target, phase, normal_weight):
    """Why "auto" leaves the surface's own area weights off (the embedding's measure), or
    None when they go on."""
    if not phase:
        return "no nearest-point phase: the embedding's measure"
    if not normal_weight > 0:
        return "normal_weight 0: no derivatives to measure the surface's area by"
    coarse, kind = _coarse(target)
    if coarse:
        return (f"{kind}: the weights follow its guessed normals at its positions' cost; "
                f"the embedding's measure")
    return None


def _plan(target, o, net, elapsed=0.0):
    """Fill the options left to "auto" (None) from the target's detail; returns the choices
    made (option -> {"value", "why"})."""
    choices = {}
    cells = hasattr(target, "sample_faces")    # faces (or cells) to weight by their error
    if o["sampling"] == "error" and not cells:
        raise ValueError("sampling='error' needs a target with cells to weight (fit_mesh's "
                         "faces, fit_shape's parameter sphere) by their error; this one draws "
                         "its points itself: use sampling='area'")
    if o["vertex_fraction"] and not hasattr(target, "sample_vertices"):
        raise ValueError(f"vertex_fraction={o['vertex_fraction']:g} needs a mesh target "
                         f"(fit_mesh); an analytic map has no vertices: use 0")
    readout = []        # the detail read-out (readout_errors), measured once when needed

    def read_out():
        if not readout:
            readout.extend(readout_errors(target))
        return readout

    sampled, why = _smooth_sample(target, o, net, read_out)
    sample = sampled is not None
    if why is not None:
        choices["smooth_sample"] = {"value": sampled or False, "why": why}
    if sample:      # positions only: the normals are an estimate, the vertices the data
        o["normal_weight"] = 0.0
        choices["normal_weight"] = {"value": 0.0, "why": "its vertices sample a smooth "
                                    "surface: its interpolated normals are only an estimate of "
                                    "the surface they lie on"}
        if o["closest_after"] is None:
            o["closest_after"] = 1.0
            choices["closest_after"] = {"value": 1.0, "why": "its vertices sample a smooth "
                                        "surface: its points are matched where the embedding "
                                        "puts them, only the tangential error relaxed"}
    if o["tangent_weight"] is None:
        o["tangent_weight"] = SAMPLE_TANGENT_WEIGHT if sample else 1.0
        choices["tangent_weight"] = {
            "value": o["tangent_weight"],
            "why": "its vertices sample a smooth surface: the fit need not follow the "
                   "embedding's piecewise-linear parameters, only pass through its points"
                   if sample else "the plain squared distance"}
    if o["vertex_fraction"] is None:
        o["vertex_fraction"], why = _vertex_fraction(target, sample)
        if why is not None:
            choices["vertex_fraction"] = {"value": o["vertex_fraction"], "why": why}
    nearest = hasattr(target, "closest")      # targets at the nearest mesh point
    if o["closest_after"] is not None and o["closest_after"] < 1.0 and not nearest:
        raise ValueError(f"closest_after={o['closest_after']:g} needs a mesh target "
                         f"(fit_mesh), whose nearest points are the targets; this target is "
                         f"matched through its parametrisation: use 1")
    if o["closest_after"] is None and (not nearest or net is not None):
        o["closest_after"] = 1.0
        choices["closest_after"] = {
            "value": 1.0, "why": "a warm start: the targets stay those of the "
            "parametrisation" if nearest else "no mesh: the targets are the map's own"}
    if o["closest_normal_weight"] is None:
        a = getattr(target, "mean_face_area", None)
        coarse, kind = _coarse(target)
        if o["normal_weight"] == 0.0:
            o["closest_normal_weight"] = 0.0
            if nearest:
                choices["closest_normal_weight"] = {
                    "value": 0.0, "why": "normal_weight 0: no derivatives, so no normal term "
                                         "in the nearest-point phase either"}
        elif coarse:
            o["closest_normal_weight"] = COARSE_CLOSEST_NORMAL
            choices["closest_normal_weight"] = {
                "value": COARSE_CLOSEST_NORMAL,
                "why": f"{kind}: its interpolated normals are guesses that no surface through "
                       f"its vertices follows; the positions lead"}
        elif nearest and a is not None:
            o["closest_normal_weight"] = min(CLOSEST_NORMAL_MAX, CLOSEST_NORMAL_AREA * a)
            choices["closest_normal_weight"] = {
                "value": o["closest_normal_weight"],
                "why": f"{CLOSEST_NORMAL_AREA:g} x the mean face area ({a:.3g}, normalised), "
                       f"at most {CLOSEST_NORMAL_MAX:g}: a finer mesh leans more on its "
                       f"positions"}
        else:       # no faces to measure (or no nearest points at all): the safe cap
            o["closest_normal_weight"] = CLOSEST_NORMAL_MAX
    if o["normal_huber"] is None and nearest:
        coarse, kind = _coarse(target)
        if coarse:
            o["normal_huber"] = 0.0
            choices["normal_huber"] = {
                "value": 0.0, "why": f"{kind}: its interpolated normals are guesses; the "
                                     f"squared normal loss, as its figures were measured"}
    exact = hasattr(target, "sample_jet")     # derivatives along the sphere as data
    for name in DERIVATIVE_WEIGHTS:
        if o[name] and not exact:
            raise ValueError(NO_JACOBIAN.format(name, o[name]))
    if o["sampling"] is None and not cells:
        o["sampling"] = "area"
        choices["sampling"] = {"value": "area", "why": "the target draws its own points: no "
                               "cells to weight by their error"}
    if net is not None:
        # fine-tuning (flows, refits): the smooth end's rate and warm-up, nothing measured;
        # the network's own width
        for k in ("lr", "warmup", "batch", "sampling", "optimizer"):
            if o[k] is None:
                o[k] = AUTO["smooth"][k]
        for k in ("width", "depth"):
            if o[k] is None:
                o[k] = getattr(net, k)
        if o["normal_huber"] is None:
            o["normal_huber"] = 0.0
            choices["normal_huber"] = {"value": 0.0, "why": "a warm start: the squared normal "
                                       "loss, as its figures were measured"}
    # "exact" for an analytic map; anything else is parametrised like a mesh
    param = "exact" if getattr(target, "parametrisation", None) == "exact" else "embedding"
    todo = [k for k in ("input_scale", "lr", "warmup", "batch", "sampling", "optimizer",
                        "width", "depth", "closest_after") if o[k] is None and net is None]
    if o["steps"] is None and o["time_budget"] is None:
        todo.append("time_budget")
    if todo:
        d, dn = read_out()
        vals, t = _auto_values(d, param, dn)
        kind = "smooth" if t == 0 else "detailed" if t == 1 else f"between ({t:.2f})"
        choices["detail"] = {"value": d, "why": f"{kind}: read-out error of scale-4 features; "
                             f"smooth <= {DETAIL_RANGE[0]:g}, detailed >= {DETAIL_RANGE[1]:g}"
                             f" (or the normals', whichever is further)"}
        choices["normal_detail"] = {
            "value": dn, "why": f"the same read-out's error on the unit normals; smooth <= "
                                f"{NORMAL_DETAIL_RANGE[0]:g}, detailed >= "
                                f"{NORMAL_DETAIL_RANGE[1]:g}"}
        for k in todo:
            v = vals[k]
            if k == "time_budget":
                v = max(v - elapsed, 10.0)
            elif k in ("warmup", "batch", "depth"):
                v = int(round(v))
            elif k == "width":          # a multiple of 16, as the products like it
                v = int(16 * round(v / 16))
            elif k == "input_scale" and sampled == "rippled":
                v = min(v, RIPPLED_INPUT_SCALE)
            o[k] = v
            choices[k] = {"value": v, "why": f"{kind} target"
                          + (f": an analytic map's {_EXACT_WHAT[k]}" if k in AUTO_EXACT
                             and param == "exact" and t > 0 else "")
                          + (f"; at most {EXACT_INPUT_SCALE_MAX:g} for an analytic map"
                             if k == "input_scale" and param == "exact"
                             and v >= EXACT_INPUT_SCALE_MAX else "")
                          + (f"; at most {RIPPLED_INPUT_SCALE:g} for ripples sampled at the "
                             f"vertices alone, which pin down no finer features"
                             if k == "input_scale" and sampled == "rippled"
                             and v >= RIPPLED_INPUT_SCALE else "")
                          + (f"; {vals[k]:.0f} s in all less {elapsed:.1f} s of embedding"
                             if k == "time_budget" and elapsed else "")
                          + (_SAMPLING_WHY[v] if k == "sampling" else "")
                          + (_closest_why(v) if k == "closest_after" else "")
                          + (_OPTIMIZER_WHY[v] if k == "optimizer" else "")}
    for name, (auto, why) in BY_PARAMETRISATION.items():
        if o[name] is None:
            o[name] = auto[param]
            choices[name] = {"value": o[name], "why": why[param]}
    phase = nearest and o["closest_after"] < 1.0
    conflict = option_conflict(o, nearest, phase)
    if conflict:
        raise ValueError(conflict)
    if o["area_weight_max"] is None:
        off = _area_weights_off(target, phase, o["normal_weight"])
        o["area_weight_max"] = 0.0 if off else AREA_WEIGHT_MAX
        if nearest:         # a mesh: recorded either way (an analytic map has no phase)
            choices["area_weight_max"] = {
                "value": o["area_weight_max"],
                "why": off or f"the nearest-point phase weighs each point by the fitted "
                              f"surface's area element over the embedding's, within a factor "
                              f"{AREA_WEIGHT_MAX:g}: the fit is judged over the surface it "
                              f"makes"}
    if o["second_moment_decay"] is None and o["optimizer"] == "soap":
        o["second_moment_decay"] = SECOND_MOMENT_DECAY[param]
        choices["second_moment_decay"] = {"value": o["second_moment_decay"],
                                          "why": _DECAY_WHY[param]}
    for name, (auto, what) in DERIVATIVE_WEIGHTS.items():
        if o[name] is None:
            o[name] = auto["exact" if exact else "embedding"]
            choices[name] = {
                "value": o[name],
                "why": f"an analytic map: its {what} along the sphere are exact data" if exact
                       else "no exact derivatives (a mesh's are its embedding's, piecewise "
                            "linear)"}
    if o["steps"] is None:
        choices["steps"] = {"value": None, "why": "as many as fit in the time budget; the "
                            "learning rate decays with the time elapsed"}
    return choices


def _probe_step_time(o, repeats=2):
    """Seconds per training step of the options' (FitOptions) network and batch, measured on
    this machine (a fresh network, random points: about a second)."""
    g = np.random.default_rng(0)
    # an automatic width, depth or batch is not known yet: the cheapest it can be (lenient)
    width = o.width or min(end["width"] for end in AUTO.values())
    depth = o.depth if o.depth is not None else min(
        [end["depth"] for end in AUTO.values()] + [AUTO_EXACT["depth"]])
    net = ResidualMLP(width=width, depth=depth, seed=g, dtype=np.dtype(o.dtype))
    batch = o.batch or min(end["batch"] for end in AUTO.values())
    p = uniform_sphere(batch, g)
    pc, R = p.astype(net.dtype), tangent_frame(p).astype(net.dtype)

    def loss_fn(y, JD, sl):
        return float((y * y).sum()), 2 * y, np.zeros_like(JD)

    net.value_and_grad(pc, loss_fn, order=1, directions=R)      # compiles on a first call
    t = time.perf_counter()
    for _ in range(repeats):
        net.value_and_grad(pc, loss_fn, order=1, directions=R)
    return (time.perf_counter() - t) / repeats


def _schedule(o):
    if o["schedule"] == "constant":
        return Schedule("constant", o["lr"], warmup=o["warmup"])
    return Schedule("cosine", o["lr"], total=o["steps"] or _MAX_AUTO_STEPS, lr_min=o["lr_min"],
                    warmup=o["warmup"])

