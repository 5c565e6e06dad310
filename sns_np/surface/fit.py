"""Fitting a SphericalNeuralSurface to a mesh or an analytic surface (paper, section 3.1).

The network is trained in a normalised frame (surface centred at its area centroid and scaled
to area 4 pi) on fresh random samples every step:

    loss = 1/N sum |net(p_i) - q_i|^2 + w_n 1/N sum |n(p_i) - n_i|^2

where q_i is the target point that corresponds to the sphere point p_i and n_i the target's
unit normal. The two tangent derivatives that the normal needs come from a 3-stream
directional jet (value, d/de_u, d/de_v) and the gradient from the engine's reverse mode.

Training runs in float32 by default (about twice as fast on a CPU; see docs/fitting.md for the
measured accuracy), and the returned surface is converted to float64 for evaluation.
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from .._atomic import exclusive, remove_stale_temporaries
from .._progress import Progress
from .._signals import deferred_signals
from .._validation import as_generator
from ..errors import DivergenceError, FitInterrupted, ModelFileError
from ..geometry import area_element_from_jets, tangent_frame, tangent_jacobian
from ..nn.mlp import ResidualMLP
from ..nn.optim import make_optimizer
from ..options import (  # noqa: F401  (AUTO, DETAIL_RANGE: the planning constants, re-exported)
    AUTO,
    CHECKPOINT_SECONDS,
    CHECKPOINT_STEPS,
    DETAIL_RANGE,
    MESH_SMOOTHING,
    FitOptions,
    check_smooth,
)
from ..protocol import surface_jet
from ..sampling import uniform_sphere
from ._adaptive import ErrorSampler
from ._checkpoint import (
    _check_checkpoint_options,
    _CheckpointCadence,
    _load_checkpoint,
    _resume_key,
    _save_checkpoint,
)
from ._plan import (
    _MAX_AUTO_STEPS,
    DERIVATIVE_WEIGHTS,
    NO_JACOBIAN,
    _ClockCosine,
    _plan,
    _probe_step_time,
    _schedule,
    detail,
    option_conflict,
    readout_errors,
)
from ._readouts import _gauss_newton_readout, _ridge_readout
from ._targets import _MeshTarget, _ShapeTarget
from .losses import (
    hessian_loss,
    jacobian_loss,
    normals_from_tangents,
    own_area_weights,
    position_normal_loss,
)
from .model import SphericalNeuralSurface

__all__ = ["FitReport", "FitOptions", "fit_mesh", "fit_shape", "fit_sampler", "detail",
           "readout_errors", "DEFAULTS"]

#: the default fitting options as a dict (kept for older code: :class:`FitOptions` holds them)
DEFAULTS = FitOptions().to_dict()


@dataclass
class FitReport:
    """What a fit did and how well it fits held-out points (in the input's units).

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> S, report = fit_shape(Ellipsoid(1.0, 1.3, 0.7), width=16, depth=1, steps=20,
    ...                       batch=256, n_eval=500, progress=False)
    >>> report.steps, report.stopped, report.options["input_scale"]   # smooth: scale 4
    (20, 'step budget', 4.0)
    >>> sorted(report.choices)                         # what "auto" chose, and why
    ['closest_after', 'detail', 'hessian_weight', 'input_scale', 'jacobian_weight', 'lr',
     'lr_min', 'normal_detail', 'normal_huber', 'normal_weight', 'optimizer', 'sampling',
     'tangent_weight', 'warmup']
    """

    steps: int = 0
    seconds: float = 0.0
    stopped: str = ""
    final_loss: float = float("nan")
    #: held-out position error |S(p) - q| (mean, RMS, max) and relative to the bbox diagonal
    position_mean: float = float("nan")
    position_rms: float = float("nan")
    position_max: float = float("nan")
    bbox_diagonal: float = float("nan")
    #: held-out angle between the surface normal and the target normal, degrees
    normal_mean_deg: float = float("nan")
    normal_max_deg: float = float("nan")
    #: a mesh only, independent of the parametrisation: held-out mean distance from the
    #: surface to the mesh, and angle to the mesh's interpolated normal at the nearest point
    #: (means over the surface's area)
    distance_mean: float = float("nan")
    closest_normal_mean_deg: float = float("nan")
    #: a mesh only: mean distance from the mesh's vertices to the surface (each projected
    #: from its own sphere point), the side that shows a feature the surface skips
    vertex_distance_mean: float = float("nan")
    #: an analytic map only: the position term's least-squares read-out applied after
    #: training (:func:`closing_readout`), as ``{"translation": t}`` (the centre's change,
    #: the surface's units) and ``"readout_change"`` (``|dW3| / |W3|``, Frobenius norms,
    #: ``W3`` as trained); empty for any other target
    closing_readout: dict = field(default_factory=dict)
    history: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    #: what the options left to "auto" became, and why (option -> {"value", "why"})
    choices: dict = field(default_factory=dict)
    #: plain-language remarks on the result (for instance a budget too short for the goals)
    notes: list = field(default_factory=list)

    #: fidelity goals (held-out): normal angle in degrees and mean distance relative to the
    #: bounding-box diagonal; for a mesh against the mesh at the nearest point, for an
    #: analytic map against the map
    GOALS = {"normal_mean_deg": 1.5, "position_relative": 1e-3}

    def add_quality_notes(self):
        """Note the goals a fit missed, and whether its budget is what limited it.

        Examples
        --------
        >>> r = FitReport(steps=10, seconds=1.0, stopped="step budget", position_mean=0.1,
        ...               bbox_diagonal=1.0, normal_mean_deg=3.0).add_quality_notes()
        >>> r.notes[0][:50]
        'the step budget (10 steps, 1 s) was too short to r'
        """
        # a mesh's goals are geometric (the surface against the mesh, whatever the
        # parametrisation); an analytic map's are against the map
        mesh = np.isfinite(self.distance_mean)
        normal = self.closest_normal_mean_deg if mesh else self.normal_mean_deg
        position = self.two_sided_distance_relative if mesh else self.position_relative
        what = ("normal error at the nearest mesh point", "two-sided distance to the mesh") \
            if mesh else ("normal error", "position error")
        missed = []
        if normal > self.GOALS["normal_mean_deg"]:
            missed.append(f"{what[0]} {normal:.2f} deg > {self.GOALS['normal_mean_deg']} deg")
        if position > self.GOALS["position_relative"]:
            missed.append(f"{what[1]} {position:.2e} > "
                          f"{self.GOALS['position_relative']:g} of the diagonal")
        if missed and self.stopped in ("step budget", "time budget"):
            self.notes.append(f"the {self.stopped} ({self.steps} steps, {self.seconds:.0f} s) "
                              f"was too short to reach the fidelity goals: "
                              f"{'; '.join(missed)}; a longer time_budget keeps improving it")
        return self

    @property
    def position_relative(self) -> float:
        return self.position_mean / self.bbox_diagonal

    @property
    def distance_relative(self) -> float:
        return self.distance_mean / self.bbox_diagonal

    @property
    def two_sided_distance_relative(self) -> float:
        """The mean of the surface-to-mesh and vertices-to-surface distances, relative to the
        diagonal (the surface-to-mesh one alone if the other was not measured).

        Examples
        --------
        >>> FitReport(bbox_diagonal=2.0, distance_mean=0.1,
        ...           vertex_distance_mean=0.3).two_sided_distance_relative
        0.1
        """
        if not np.isfinite(self.vertex_distance_mean):
            return self.distance_relative
        return 0.5 * (self.distance_mean + self.vertex_distance_mean) / self.bbox_diagonal

    def summary(self) -> str:
        """The report in a few lines: steps, time, held-out errors and notes.

        Examples
        --------
        >>> r = FitReport(steps=10, seconds=1.0, stopped="step budget", position_mean=1e-4,
        ...               position_rms=1e-4, position_max=3e-4, bbox_diagonal=1.0,
        ...               normal_mean_deg=0.5, normal_max_deg=2.0)
        >>> r.summary()[:40]
        '10 steps in 1.0 s (step budget); held-ou'
        """
        return (f"{self.steps} steps in {self.seconds:.1f} s ({self.stopped}); held-out "
                f"position error mean {self.position_mean:.3g} (= {self.position_relative:.2e}"
                f" of the bbox diagonal), RMS {self.position_rms:.3g}, max "
                f"{self.position_max:.3g}; normal error mean {self.normal_mean_deg:.3f} deg, max "
                f"{self.normal_max_deg:.2f} deg"
                + (f"; against the mesh: distance {self.distance_relative:.2e} of the bbox "
                   f"diagonal" + (f" (its vertices to the surface "
                                  f"{self.vertex_distance_mean / self.bbox_diagonal:.2e})"
                                  if np.isfinite(self.vertex_distance_mean) else "")
                   + f", normal error {self.closest_normal_mean_deg:.3f} deg at the "
                   f"nearest point" if np.isfinite(self.distance_mean) else "")
                + (f"; closing read-out: translation "
                   f"{np.linalg.norm(self.closing_readout['translation']):.3g}, read-out "
                   f"change {self.closing_readout['readout_change']:.3g}"
                   if self.closing_readout else "")
                + "".join(f"\nnote: {n}" for n in self.notes))

    def to_json(self) -> dict:
        """The report as a JSON-serialisable dict (kept in the model's metadata).

        Examples
        --------
        >>> import json
        >>> d = FitReport(steps=3, bbox_diagonal=2.0, position_mean=0.1).to_json()
        >>> d["steps"], d["position_relative"], len(json.dumps(d)) > 0
        (3, 0.05, True)
        """
        d = asdict(self)
        d["history"] = {k: list(map(float, v)) for k, v in self.history.items()}
        d["position_relative"] = self.position_relative
        d["distance_relative"] = self.distance_relative
        d["two_sided_distance_relative"] = self.two_sided_distance_relative
        return d


# ------------------------------------------------------------------------------ public API

def fit_mesh(V, F, *, Vs=None, check=True, smooth=MESH_SMOOTHING[0], creases="auto",
             **options):
    """Fit a SphericalNeuralSurface to a closed genus-0 triangle mesh.

    Parameters
    ----------
    V : (n, 3) float array, vertex positions
    F : (m, 3) int array, triangles
    Vs : (n, 3) float array, optional
        A spherical embedding of V (unit vectors, fold-free); computed with
        :func:`sns_np.mesh.spherical_embedding` when omitted.
    check : bool
        Run :func:`sns_np.mesh.check` first (raises a specific MeshError on defects).
    smooth : {"phong", "normals", "none"}
        The position targets between the vertices. "phong" (default): the Phong-tessellated
        mesh (the vertex normals bend each triangle like the surface it samples, one
        triangle at a time); "normals": the surface over the mesh whose normals follow its
        interpolated vertex normals, held at its vertices (:class:`sns_np.mesh.NormalHeights`,
        a sparse solve of a few seconds before the fit, counted in its budget; spot's normal
        error 0.72 -> 0.54 degrees, the other shared meshes level, SPIKE's mesh further from
        its truth); "none": the flat triangles. Recorded in ``report.choices["smooth"]`` and
        the model's metadata. docs/fitting.md, "The mesh's normals as a target".
    creases : "auto", "none" or float
        Edges along which the target normals are not averaged: with an angle in degrees, the
        two sides of every edge whose faces turn by more than it keep their own normals
        (:func:`sns_np.mesh.corner_normals`), so the fit may keep the edge sharp. "auto"
        (default): ``CREASE_ANGLE`` (60) on a mesh too coarse for its vertex normals to be
        followed across its sharp edges (a coarse mesh: its Phong tessellation more than
        ``CREASE_GAP``, 1e-3 of the diagonal, off its triangles, or its vertex normals
        turning by more than ``COARSE_TURN``, 20 degrees, across a median edge), none
        otherwise, with ``smooth="normals"``, which refuses an angle, and on a mesh coarse
        for its curvature alone when the normal weight is left to auto (it is then fitted by
        its positions: ``normal_weight``); recorded in the model's metadata.
        docs/fitting.md, "Meshes with sharp edges".
    **options
        The fitting options (:class:`FitOptions`: steps, batch, lr, time_budget, ...) and
        those of :func:`fit_sampler` (checkpoint, progress, ...).

    Returns
    -------
    surface : SphericalNeuralSurface, in the mesh's units, float64
    report : FitReport (held-out errors against the mesh)

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    >>> S, report = fit_mesh(V, F, width=16, depth=1, steps=30, batch=256, n_eval=500,
    ...                      progress=False)            # tiny; the defaults adapt to the mesh
    >>> S(np.array([[0.0, 0.0, 1.0]])).shape, report.steps, S.metadata["smooth"]
    ((1, 3), 30, 'phong')
    """
    check_smooth(smooth, creases)
    _check_early(options, mesh=True)
    for name in DERIVATIVE_WEIGHTS:             # before the embedding, not after it
        if options.get(name):
            raise ValueError(NO_JACOBIAN.format(name, options[name]))
    t0 = time.perf_counter()
    # a mesh sampled at its vertices may be fitted by its positions ("auto" normal weight,
    # a fresh fit): its creases are then decided with that in mind
    positions = options.get("normal_weight") is None and options.get("net") is None
    target = _MeshTarget(V, F, Vs, check=check, verbose=options.get("progress", True),
                         smooth=smooth, crease_angle=creases, positions=positions)
    meta = {"source": options.pop("source", "mesh"), "n_vertices": int(len(V)),
            "n_faces": int(len(F)), "area": target.area, "smooth": target.smooth,
            "crease_angle": target.crease_angle}
    return fit_sampler(target, metadata=meta, elapsed_before=time.perf_counter() - t0,
                       **options)


def fit_shape(shape, **options):
    """Fit a SphericalNeuralSurface directly to an analytic surface map (as the paper does).

    Sphere points are drawn uniformly (for a detailed map, where the recent error is, with
    importance weights: ``sampling``); targets are ``shape(p)``, its exact normals and its
    first and second derivatives along the sphere (``jacobian_weight``,
    ``hessian_weight``). The fit ends with the read-out layer and shift that minimise the
    position term given the trained features (:func:`closing_readout`: a change of a few
    per cent of the read-out, which noisy steps and the derivative terms leave), recorded
    in ``report.closing_readout``.
    Options as :func:`fit_sampler`. Returns (surface, report).

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> S, report = fit_shape(Sphere(2.0), width=16, depth=1, steps=100, batch=256,
    ...                       n_eval=500, progress=False)
    >>> x = S(np.array([[0.0, 0.0, 1.0]]))
    >>> bool(abs(np.linalg.norm(x) - 2.0) < 0.1)       # in the shape's units
    True
    """
    _check_early(options)
    target = _ShapeTarget(shape)
    meta = {"source": options.pop("source", f"shape:{type(shape).__name__}"),
            "area": target.area}
    return fit_sampler(target, metadata=meta, **options)


def fit_sampler(target, *, metadata=None, net=None, elapsed_before=0.0, checkpoint=None,
                checkpoint_every=CHECKPOINT_STEPS, checkpoint_seconds=CHECKPOINT_SECONDS,
                resume=False, progress=True,
                callback=None, history_every=50, **options):
    """The training loop behind :func:`fit_mesh` and :func:`fit_shape`.

    The fitting options are the fields of :class:`FitOptions`, passed as keyword arguments
    (``None`` leaves an option at its default; an unknown name is refused before any work).
    Their defaults and one-line help are the dataclass's; the notes below say why they are
    what they are.

    Parameters
    ----------
    target : object with ``sample(n, rng) -> (p, q, normals)`` and ``evaluate_at(p) -> (q,
        normals)`` in the normalised frame, and attributes ``center``, ``scale``,
        ``bbox_diagonal``, ``fingerprint``; optionally ``parametrisation``, ``"exact"``
        for an analytic map (the default normal weight depends on it; any other target is
        treated as a mesh's ``"embedding"``), and ``sample_jet(n, rng, second=False) -> (p,
        q, normals, JT, ST)``, ``sample``'s points with the exact derivatives JT (n, 3, 2)
        along ``tangent_frame(p)`` (the Jacobian loss's data) and, with ``second``, the
        second derivatives along the sphere ST (n, 3, 2, 2) (the Hessian loss's; else None)
    net : ResidualMLP, optional
        Start from this network (fine-tuning; e.g. flows) instead of a fresh one.
    width, depth : int
        Architecture of a fresh network. Depth: the reference's 8 blocks. Width: chosen
        from the target's :func:`detail`, the reference's 256 for a smooth target and 128
        for a detailed one: a quarter of the products per step, so about four times the
        steps in the same time, and detail is limited by the steps, not by the width
        (docs/fitting.md, "The network's width"); a detailed analytic map gets 192 wide and
        4 deep (``sns_np.options.AUTO_EXACT``). A warm start ``net`` keeps its own.
    steps : int, optional
        Step budget. Default: as many steps as fit in ``time_budget``, with the cosine decay
        running on the clock (over the fraction of the budget elapsed).
    batch : int
        Fresh samples per step. Default: chosen from the target's :func:`detail`, the
        reference's for a smooth target and a quarter of it for a detailed one: in the same
        time, 3.3 times as many steps of a quarter of the samples fit detail better
        (docs/fitting.md). A warm start ``net`` uses the smooth end's.
    lr, lr_min, schedule, warmup, optimizer
        Cosine decay from ``lr`` to ``lr_min`` with a linear warm-up of ``warmup`` steps.
        ``lr``, ``warmup`` and ``optimizer`` default to a choice from the target's
        :func:`detail` (``AUTO``; a warm start ``net`` uses the smooth end's): Adam for a
        smooth target, SOAP (:class:`~sns_np.nn.SOAP` on the hidden matrices ``W1``, ``W2``,
        Adam on the rest) for a detailed one, which learns detail in fewer steps.
        ``optimizer="rmsprop", lr=1e-4, schedule="constant", normal_weight=1e-4`` reproduces
        the reference's settings.
    second_moment_decay : float in [0, 1)
        Adam's and SOAP's second-moment decay ``b2`` (refused with another optimiser).
        Default (``SECOND_MOMENT_DECAY``), for SOAP: 0.95 on a mesh, whose fit learns
        detail faster with a short memory of the gradients' scale, and 0.999 on an
        analytic map, whose curvature wants the long one; Adam keeps 0.999.
    normal_weight : float
        Weight of the normal term. Default (``NORMAL_WEIGHT``): 1 for a mesh, where the
        position term is dominated by the tangential error of the spherical embedding and the
        reference's 1e-4 would leave nothing to steer past it; 0.1 for an analytic map, whose
        parametrisation is exact and where weight 1 lets the network trade position for
        normals. docs/fitting.md measures both. On a detailed mesh whose vertices sample a
        smooth surface (:func:`~sns_np.surface._targets.smooth_sampling`: a fine mesh whose
        :func:`~sns_np.mesh.curvature_jitter` is at most ``SAMPLE_JITTER``, 0.15, or one
        coarse for its curvature alone, rippled) "auto" takes 0 and with it that case's
        ``vertex_fraction``, ``closest_after`` and ``tangent_weight`` (a rippled mesh also no
        creases and an ``input_scale`` of at most ``RIPPLED_INPUT_SCALE``, 16): its vertices
        are the data, its interpolated normals an estimate (docs/fitting.md, "A fine sample
        of a smooth surface, by default"). Any other value keeps the normal-following
        defaults.
    normal_huber : float, degrees in [0, 180]
        The angle beyond which a point's normal error counts by its size, not its square (a
        pseudo-Huber loss, :func:`~sns_np.surface.losses.position_normal_loss`), in both
        phases of a mesh's fit; 0: squared throughout. Default (``NORMAL_HUBER``): 4 for a
        mesh, judged by its mean angle, where the squared loss lets a few points of large
        error (fingers, ears, targets that disagree) steer the fit; 0 for a coarse mesh,
        whose interpolated normals are guesses, an analytic map and a warm start.
        docs/fitting.md, "A robust normal loss", measures it.
    jacobian_weight : float
        Weight of the loss on the derivatives along the sphere, ``|dS(e_u) - dS_t(e_u)|^2 +
        |dS(e_v) - dS_t(e_v)|^2`` (:func:`~sns_np.surface.losses.jacobian_loss`), for a
        target with exact derivatives (``sample_jet``: an analytic map). Default
        (``JACOBIAN_WEIGHT``): 0.1 for an analytic map, where it cuts the curvature error
        severalfold for a second jet of the map per step (the network's derivatives are
        those the normal term already needs; at weight 1 the position led less, and the
        curvature at the closest point of the map was worse); 0 for a mesh, whose
        derivatives are its embedding's, and any other target (a mesh refuses a positive
        weight).
    hessian_weight : float
        Weight of the loss on the second derivatives along the sphere, ``sum_ab |S_ab -
        T_ab|^2`` with ``S_ab = D2S(e_a, e_b) - delta_ab dS(p)``
        (:func:`~sns_np.surface.losses.hessian_loss`), for a target with exact derivatives.
        Default (``HESSIAN_WEIGHT``): 1e-4 for an analytic map (a thousandth of the Jacobian
        weight, as at 1 and 1e-3 before): a step costs about twice as much (the engine's
        reverse mode through second-order jets), and with the same time the curvature error
        still ends lower (1.5-1.9 times on FLOWER and TREE when measured at 1e-3); 0 for any
        other target (a mesh refuses a positive weight). Larger weights trade position for
        second derivatives.
    dtype : {"float32", "float64"}
        Training precision (the result is float64).
    init : {"ridge", "random"}
        "ridge" sets the output layer of a fresh network by regularised least squares on its
        initial features, so training starts from the best linear read-out instead of a point
        (see docs/fitting.md for the measured effect).
    input_scale : float
        First-layer scale of a fresh network (``W0`` std ``input_scale / sqrt(3)``). Default:
        chosen from the target's :func:`detail`, small for a smooth target (a larger scale
        makes the curvature of a coarse mesh of a smooth shape follow its facets) and ten
        times larger for a detailed one (features that vary fast enough for ears, horns and
        faces), interpolated in between, and at most 16 for an analytic map, whose
        derivatives are supervised too (``sns_np.options.EXACT_INPUT_SCALE_MAX``;
        docs/fitting.md).
    time_budget : float, seconds, optional
        Stop when exceeded (checked every step). Default when ``steps`` is not given either:
        chosen from the target's detail (240 s for a smooth target, 540 s for a detailed
        mesh, 1800 s for a detailed analytic map, whose curvature keeps improving), in all,
        less the ``elapsed_before`` seconds already spent (the embedding). A ``steps`` that
        this budget cannot reach is refused before the fit starts (by :func:`fit_mesh`,
        :func:`fit_shape`).
    sampling : {"area", "error"}
        How training points are drawn: uniformly (by area on a mesh, on the sphere for an
        analytic map), or with probability that follows each cell's recent error (a patch
        of the mesh's faces; a geodesic triangle of the parameter sphere for an analytic
        map), mixed with the uniform draw, each point carrying the importance weight that
        keeps the expected loss the uniform one (:mod:`sns_np.surface._adaptive`). Default:
        chosen from the target's detail (``AUTO``, docs/fitting.md); ``"area"`` for a warm
        start and for a target that draws its points itself.
    vertex_fraction : float in [0, 1]
        Share of each batch drawn at the mesh's vertices (uniformly, importance weight 1),
        the rest as ``sampling`` says. A mesh's vertices are its only exact data: between
        them positions and normals are interpolated, and a mesh of a smooth surface carries
        the interpolation's error into its targets (docs/fitting.md, "The mesh's vertices").
        0 draws on the faces only; a mesh only. Default: ``COARSE_VERTEX_FRACTION`` (0.25) on
        a coarse mesh (as for ``creases``: coarse for its size or for its curvature),
        ``SAMPLE_VERTEX_FRACTION`` (0.5) on a mesh whose vertices sample a smooth surface
        (as for ``normal_weight``), 0 on any other mesh and on an analytic map.
    tangent_weight : float
        Weight of the tangential part of the position error (1: the plain squared distance);
        smaller values let points slide along the target (docs/fitting.md). Default: 1;
        ``SAMPLE_TANGENT_WEIGHT`` (0.01) on a mesh whose vertices sample a smooth surface (as
        for ``normal_weight``), whose fit need not follow the embedding's piecewise-linear
        parameters of its points.
    closest_after : float in [0, 1]
        A mesh only: after this fraction of the fit (of the time budget, or of the steps),
        the targets of each training point are taken at the mesh point nearest the network's
        value ``S(p)`` (:meth:`_MeshTarget.closest`: the Phong point and interpolated normal
        there), not at the embedding's correspondence of ``p``. The loss is then the squared
        distance to the mesh (whose gradient is ``2 (S(p) - c)``) plus
        ``closest_normal_weight`` times the normal error there, plus ``anchor_weight`` times
        the squared distance to the correspondence, which keeps the parametrisation from
        drifting without asking the network to follow the embedding's piecewise-linear
        stretch. Default: chosen from the target's detail (``AUTO``): 1 (never) for a smooth
        mesh, 0.2 for a detailed one; 1 for an analytic map, a warm start and a mesh whose
        vertices sample a smooth surface (as for ``normal_weight``). docs/fitting.md, "The
        nearest-point phase".
    closest_normal_weight : float
        The weight of the nearest-point phase's normal term. Default: 50 times the mesh's
        mean face area in normalised units (total area 4 pi), at most 0.1 (``options.
        CLOSEST_NORMAL_AREA``): a finer mesh's positions carry more of its shape, so its fit
        leans on them more (spot, 5,856 faces: 0.107, so 0.1; the armadillo, 43,240: 0.0145). Weight
        1 is unstable there (the target normal moves with the point). On a coarse mesh (as
        for ``vertex_fraction``) ``COARSE_CLOSEST_NORMAL``, 0.01: its interpolated normals
        are guesses that no surface through its vertices follows.
    anchor_weight : float
        The weight of the nearest-point phase's anchor to the correspondence (1).
    area_weight_max : float, 0 or >= 1
        A mesh's nearest-point phase only: each training point's terms are weighted by the
        fitted surface's area element over the embedding's at that point, clipped to
        ``[1 / area_weight_max, area_weight_max]`` and held constant in the gradient
        (:func:`~sns_np.surface.losses.own_area_weights`). The points are drawn by the mesh's
        area through the embedding, but the fit is judged over the surface it makes; where
        the network stretches a patch of the sphere over more surface than the embedding
        does, that surface gets its share back. 0: the embedding's measure throughout.
        Default: ``options.AREA_WEIGHT_MAX`` (4) when the phase runs on a fine mesh, else 0
        (a coarse mesh keeps the embedding's measure: its interpolated normals are guesses,
        and the weights followed them at the positions' cost). It needs the normals'
        derivatives, so ``normal_weight`` 0 takes 0. docs/fitting.md, "The surface's own
        area".
    readout_every : int
        Refit the output layer every this many steps (0: never) by ``readout="gn"``
        (Levenberg-Marquardt on the full position + normal loss) or ``"ridge"`` (least
        squares on the positions only).
    tol : float, optional
        Stop when the running RMS position error, relative to the normalised size (the
        surface has area 4 pi), falls below ``tol``.
    n_eval : int
        Held-out sphere points for the report (fixed seed, not used in training).
    seed : int or Generator
        Seed of initialisation and sampling.
    checkpoint : path, optional
        .npz file written atomically every ``checkpoint_every`` steps or ``checkpoint_seconds``
        seconds, whichever comes first, on interruption and at the end (the file is kept: the
        caller removes it once the model is saved). With ``resume=True`` an existing
        checkpoint of the same target and options is continued from its step, bit for bit.
        While the fit runs it holds ``<checkpoint>.lock``: a second fit with the same
        checkpoint is refused (:class:`~sns_np._atomic.OutputBusyError`), and temporary files
        that a killed fit left beside the checkpoint are removed.
    checkpoint_every, checkpoint_seconds : int, float
        Checkpoint cadence (``CHECKPOINT_STEPS``, ``CHECKPOINT_SECONDS``): a crash loses at
        most about a minute.
    progress : bool
        Show a progress line on stderr.
    callback : callable ``callback(step, info) -> bool``, optional
        Called every ``history_every`` steps with a dict of current figures; returning True
        stops the fit.
    elapsed_before : float
        Seconds already spent on this fit before the call (the embedding); an automatic time
        budget is shortened by it.

    Returns
    -------
    (SphericalNeuralSurface, FitReport)
        The report's ``choices`` say what the options left unset became and why.

    Raises
    ------
    FitInterrupted
        On Ctrl-C (SIGINT) or SIGTERM. The signal is acted on between two optimiser steps,
        never inside an update; the checkpoint, if any, then holds the last completed step.
        A second signal stops at once (the checkpoint then holds the last periodic save).
    DivergenceError
        When the loss or gradient is not finite; the checkpoint, if any, then holds the last
        good step.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> from sns_np.surface.fit import _ShapeTarget
    >>> target = _ShapeTarget(Ellipsoid(1.0, 1.3, 0.7))  # any object with the methods above
    >>> S, report = fit_sampler(target, width=16, depth=1, time_budget=1.0, batch=256,
    ...                         n_eval=500, progress=False)    # steps sized by the clock
    >>> report.stopped, report.choices["steps"]["value"] == report.steps
    ('time budget', True)
    """
    o = FitOptions.from_kwargs(**options).to_dict()
    _check_checkpoint_options(checkpoint, checkpoint_every, checkpoint_seconds)
    t_dtype = np.dtype(o["dtype"])
    choices = _plan(target, o, net, elapsed=elapsed_before)     # fills in the "auto" options
    if getattr(target, "crease_why", None):                     # fit_mesh's targets
        choices["smooth"] = {"value": target.smooth, "why": target.smooth_why}
        choices["creases"] = {"value": target.crease_angle, "why": target.crease_why}
    rng = as_generator(o["seed"])
    key = _resume_key(target, FitOptions(**o), net)
    with contextlib.ExitStack() as hold:
        if checkpoint is not None:
            hold.enter_context(exclusive(checkpoint))       # one fit per checkpoint at a time
            remove_stale_temporaries(checkpoint)            # left by a killed fit
        state = None
        if checkpoint is not None and resume and os.path.exists(checkpoint):
            state = _load_checkpoint(checkpoint, key)
        if state is not None:
            net = state["net"].astype(t_dtype)
            rng.bit_generator.state = state["rng"]
            start, history, elapsed0 = state["step"], state["history"], state["seconds"]
        else:
            if net is None:
                net = ResidualMLP(width=o["width"], depth=o["depth"], seed=rng, dtype=t_dtype,
                                  input_scale=o["input_scale"])
                if o["init"] == "ridge":
                    _ridge_readout(net, target, rng)
            else:
                net = net.astype(t_dtype)
            start, history, elapsed0 = 0, {k: [] for k in ("step", "loss", "position_rms",
                                                          "normal_deg", "lr", "seconds")}, 0.0
        opt = make_optimizer(o["optimizer"], _schedule(o), **_optimizer_options(o, net))
        if state is not None:
            try:
                opt.load_state_dict(state["opt"])
            except ValueError as err:   # e.g. SOAP's matrices of an earlier version
                raise ModelFileError(
                    f"{checkpoint} holds an optimiser state that this fit's optimiser cannot "
                    f"take ({err}); delete it or pass another checkpoint path") from None
        sampler = ErrorSampler(target, o["batch"]) if o["sampling"] == "error" else None
        if sampler is not None and state is not None:
            sampler.load_state_dict(state["sampler"])

        # with no step count the schedule runs on the clock: its decay ends with the budget
        auto_steps = o["steps"] is None
        total = o["steps"] if not auto_steps else _MAX_AUTO_STEPS
        if auto_steps and o["schedule"] == "cosine":
            opt.schedule = _ClockCosine(opt.schedule, lambda: time.perf_counter() - t0,
                                        o["time_budget"])
        closest = o["closest_after"] < 1.0
        bar = Progress(total if not auto_steps else 1, "fit", enabled=progress)
        t0 = time.perf_counter() - elapsed0
        w = o["normal_weight"]
        tw = o["tangent_weight"]
        n_vertices = int(round(o["vertex_fraction"] * o["batch"]))
        n_faces = o["batch"] - n_vertices
        wj = o["jacobian_weight"]
        wh = o["hessian_weight"]
        order = 2 if wh else 1 if (w or wj) else 0
        if closest:
            target.nearest()        # built here, not by the engine's threads at once
        ema_pos = ema_nrm = None
        stopped = "step budget"
        step = start
        last_loss = float("nan")
        saves = _CheckpointCadence(checkpoint, checkpoint_every, checkpoint_seconds,
                                   held=start if state is not None else None)
        rng_at_step = rng.bit_generator.state         # the generator as the step began

        def write_checkpoint(rng_state=None):
            if checkpoint is not None:
                _save_checkpoint(checkpoint, net, opt, rng_state or rng.bit_generator.state,
                                 step, history, time.perf_counter() - t0, key, target, metadata,
                                 sampler)
                saves.saved(step)

        updating = False        # True while a step's parameters and moments are half-updated
        signals = deferred_signals()
        try:
            with signals:
                while step < total:
                    rng_at_step = rng.bit_generator.state
                    if (wj or wh) and sampler is None:      # an analytic map, no vertices
                        p, q, nt, JT, ST = target.sample_jet(n_faces, rng, second=bool(wh))
                        wts = None
                    elif wj or wh:                          # drawn where its error is
                        p, q, nt, JT, ST, wts = sampler.sample(n_faces, rng, jets=True,
                                                               second=bool(wh))
                    else:
                        p, q, nt, wts = _draw(target, sampler, n_faces, n_vertices, rng)
                    wc = None if wts is None else wts.astype(t_dtype)
                    errors = None if sampler is None else np.empty(len(p))
                    R = tangent_frame(p) if order else None
                    if wh:      # [e_u, e_v, p]: second derivatives along e_u, e_v and J p
                        R = np.concatenate([R, p[:, :, None]], axis=2)
                    pc = p.astype(t_dtype)
                    qc, ntc = q.astype(t_dtype), nt.astype(t_dtype)
                    parts = {}      # slice start -> its (position, normal) sums
                    JTc = JT.astype(t_dtype) if wj else None
                    STc = ST.astype(t_dtype) if wh else None

                    near = closest and _fraction_done(step, total, t0, o) >= o["closest_after"]
                    # the embedding's area element at each point of the phase (the plan left
                    # area_weight_max 0 without one); a vertex has none of its own and counts
                    # at the mean, 1
                    density = None
                    if near and o["area_weight_max"]:
                        density = np.ones(len(p), dtype=t_dtype)
                        density[:n_faces] = target.sphere_density[target.last_faces]

                    def loss_fn(y, JD, sl):
                        sw = None if wc is None else wc[sl]
                        if density is not None and JD is not None:
                            aw = own_area_weights(JD, density[sl], o["area_weight_max"])
                            sw = aw if sw is None else sw * aw
                        if near:    # the targets at the mesh points nearest y, anchored
                            qn, nn = (a.astype(t_dtype) for a in target.closest(y))
                            val, dy, dJD, pr = position_normal_loss(
                                y, JD, qn, nn, len(p), o["closest_normal_weight"],
                                sample_weight=sw, pointwise=errors is not None,
                                normal_huber=o["normal_huber"])
                            if o["anchor_weight"]:
                                va, dya, _, _ = position_normal_loss(
                                    y, None, qc[sl], None, len(p), 0.0, sample_weight=sw)
                                val += o["anchor_weight"] * va
                                dy += o["anchor_weight"] * dya
                        else:
                            val, dy, dJD, pr = position_normal_loss(
                                y, JD, qc[sl], ntc[sl], len(p), w, tangent_weight=tw,
                                sample_weight=sw, pointwise=errors is not None,
                                normal_huber=o["normal_huber"])
                        if wj:
                            val_j, dJD_j, _ = jacobian_loss(JD, JTc[sl], len(p), wj,
                                                            sample_weight=sw)
                            val += val_j
                            dJD = dJD_j if dJD is None else dJD + dJD_j
                        parts[sl.start] = (pr["position"], pr["normal"])
                        if errors is not None:
                            errors[sl] = pr["pointwise"]
                        return val, dy, dJD

                    def loss_fn2(y, JD3, D2D, sl):     # the Hessian loss's [e_u, e_v, p]
                        val, dy, dJD = loss_fn(y, JD3[:, :, :2], sl)
                        val_h, dD2D, dJp, _ = hessian_loss(
                            D2D, JD3[:, :, 2], STc[sl], len(p), wh,
                            sample_weight=None if wc is None else wc[sl])
                        dJD3 = np.zeros_like(JD3)
                        if dJD is not None:
                            dJD3[:, :, :2] = dJD
                        dJD3[:, :, 2] = dJp
                        return val + val_h, dy, dJD3, dD2D

                    # the loss is safe to run on several chunks at once: the nearest-point
                    # search of one worker overlaps the other's products
                    loss, grad = net.value_and_grad(
                        pc, loss_fn2 if wh else loss_fn, order=order,
                        directions=None if R is None else R.astype(t_dtype),
                        second=2 if wh else None, concurrent_loss=True)
                    if not np.isfinite(loss) or not np.all(np.isfinite(grad)):
                        stopped = "diverged"
                        # the parameters are still those of the last good step: save them
                        write_checkpoint(rng_at_step)
                        raise DivergenceError(
                            f"fit diverged at step {step} (loss {loss}); the parameters of "
                            f"the last good step are kept"
                            + (f" in the checkpoint {str(checkpoint)!r}" if checkpoint
                               else "") + "; a smaller lr may avoid it")
                    lr_now = opt.lr()
                    updating = True
                    opt.step(net.theta, grad)
                    if sampler is not None:
                        sampler.observe(errors[:n_faces])
                    step += 1
                    if o["readout_every"] and step % o["readout_every"] == 0:
                        if o["readout"] == "gn":
                            _gauss_newton_readout(net, target, rng, w, tw)
                        else:
                            _ridge_readout(net, target, rng)
                    updating = False
                    last_loss = loss
                    pos_ms = sum(parts[k][0] for k in sorted(parts)) / len(p)
                    nrm_ms = sum(parts[k][1] for k in sorted(parts)) / len(p)
                    ema_pos = pos_ms if ema_pos is None else 0.95 * ema_pos + 0.05 * pos_ms
                    ema_nrm = nrm_ms if ema_nrm is None else 0.95 * ema_nrm + 0.05 * nrm_ms
                    pos_rms = float(np.sqrt(ema_pos))
                    # |n - n_t|^2 = 2 - 2 cos(angle)  ->  angle = 2 asin(|n - n_t| / 2)
                    nrm_deg = float(np.degrees(2 * np.arcsin(min(1.0, np.sqrt(ema_nrm) / 2))))
                    elapsed = time.perf_counter() - t0
                    if step % history_every == 0 or step == total:
                        for k, v in (("step", step), ("loss", loss), ("position_rms", pos_rms),
                                     ("normal_deg", nrm_deg), ("lr", lr_now),
                                     ("seconds", elapsed)):
                            history[k].append(float(v))
                        if callback is not None and callback(step, {
                                "loss": loss, "position_rms": pos_rms, "normal_deg": nrm_deg,
                                "lr": lr_now, "seconds": elapsed, "net": net}):
                            stopped = "callback"
                            break
                    if auto_steps:          # the bar counts seconds of the budget
                        bar.total = max(int(o["time_budget"]), 1)
                        bar.update(min(int(elapsed), bar.total), step=step,
                                   loss=f"{loss:.2e}", pos=f"{pos_rms:.1e}",
                                   nrm=f"{nrm_deg:.2f}deg")
                    else:
                        bar.update(step, loss=f"{loss:.2e}", pos=f"{pos_rms:.1e}",
                                   nrm=f"{nrm_deg:.2f}deg")
                    if signals.received is not None:       # between two steps: stop here
                        write_checkpoint()
                        raise FitInterrupted(step, checkpoint, signals.received)
                    if saves.due(step):
                        write_checkpoint()
                    if o["tol"] is not None and step >= 20 and pos_rms < o["tol"]:
                        stopped = "tolerance"
                        break
                    if o["time_budget"] is not None and elapsed >= o["time_budget"]:
                        stopped = "time budget"
                        break
                bar.close(step if not auto_steps else bar.total, loss=f"{last_loss:.2e}")
                seconds = time.perf_counter() - t0
                write_checkpoint()
        except FitInterrupted:
            bar.close()
            raise
        except KeyboardInterrupt:
            # a second signal, or an interrupt raised by the callback: the state is whole
            # unless it landed inside an update, which is never saved
            if not updating:
                write_checkpoint()
            bar.close()
            held = step if not updating else saves.step
            raise FitInterrupted(start if held is None else held,
                                 checkpoint if held is not None else None,
                                 signals.received or "SIGINT") from None
        except DivergenceError:
            bar.close()
            raise

    surface = SphericalNeuralSurface(net.astype(np.float64), center=target.center,
                                     scale=target.scale, metadata=dict(metadata or {}))
    closing = {}
    if getattr(target, "parametrisation", None) == "exact":
        dW, t = closing_readout(surface, target)
        closing = {"translation": t.tolist(),
                   "readout_change": float(np.linalg.norm(dW) / np.linalg.norm(surface.net.W3))}
        surface.net.W3[...] += dW
        surface.center = surface.center + t
    report = _evaluate(surface, target, o["n_eval"])
    report.closing_readout = closing
    report.steps, report.seconds, report.stopped = step, seconds, stopped
    report.final_loss = float(last_loss)
    report.history = {k: np.asarray(v) for k, v in history.items()}
    if auto_steps:
        choices["steps"]["value"] = step
    report.options = {k: v for k, v in o.items()}
    report.choices = choices
    report.add_quality_notes()
    surface.metadata.update(fit=report.to_json())
    return surface, report


# ------------------------------------------------------------------------------ internals
# (the targets in _targets.py, planning "auto" in _plan.py, the checkpoint in _checkpoint.py,
# the read-out refits in _readouts.py; the options and their AUTO ends in sns_np.options)

#: the keyword arguments of fit_sampler that fit_mesh and fit_shape pass through
_PASSED = ("net", "checkpoint", "checkpoint_every", "checkpoint_seconds", "resume", "progress",
           "callback", "history_every", "source")


def _fraction_done(step, total, t0, o):
    """The fraction of the fit done: of the steps, or of the time budget on the clock."""
    if o["steps"] is not None:
        return step / total
    return (time.perf_counter() - t0) / o["time_budget"]


def _draw(target, sampler, n_faces, n_vertices, rng):
    """One batch: ``n_faces`` points on the faces (by ``sampler`` if any: drawn where the
    error is, weighted back to the same loss), then ``n_vertices`` vertices (weight 1).
    Returns ``(p, q, normals, weights or None)``."""
    if sampler is None:
        p, q, nt = target.sample(n_faces, rng)
        wts = None
    else:
        p, q, nt, wts = sampler.sample(n_faces, rng)
    if n_vertices:
        pv, qv, nv = target.sample_vertices(n_vertices, rng)
        p, q, nt = np.concatenate([p, pv]), np.concatenate([q, qv]), np.concatenate([nt, nv])
        if wts is not None:
            wts = np.concatenate([wts, np.ones(n_vertices)])
    return p, q, nt, wts


def _optimizer_options(o, net):
    """SOAP preconditions the hidden matrices (W1, W2); Adam and SOAP take the second-moment
    decay (when set); the other optimisers take no more."""
    out = {}
    if o.get("second_moment_decay") is not None:
        out["betas"] = (0.9, o["second_moment_decay"])
    if o["optimizer"] == "soap":
        ps = net.param_slices()
        out["matrices"] = [ps["W1"], ps["W2"]]
    return out


def _check_early(options, mesh=False):
    """Refuse unknown or contradictory options before any work (embedding, fitting) starts;
    ``mesh``: for a mesh's fit, which has a nearest-point phase."""
    o, rest = FitOptions.split(options, extra=_PASSED)
    conflict = option_conflict(o.to_dict(), phase=mesh)
    if conflict:
        raise ValueError(conflict)
    _check_checkpoint_options(rest.get("checkpoint"),
                              rest.get("checkpoint_every", CHECKPOINT_STEPS),
                              rest.get("checkpoint_seconds", CHECKPOINT_SECONDS))
    if o.steps is not None and o.time_budget is not None and rest.get("net") is None:
        per_step = _probe_step_time(o)
        if o.steps * per_step > 2.0 * o.time_budget:
            raise ValueError(
                f"steps={o.steps} cannot be reached in time_budget={o.time_budget:g} s: "
                f"a step of this network takes about {per_step * 1e3:.0f} ms here, so "
                f"{o.steps} steps need about {o.steps * per_step:.0f} s; pass only one "
                f"of them (time_budget alone sizes the step count to fit)")


#: sphere points of :func:`closing_readout`'s least squares
CLOSING_POINTS = 65_536
#: the largest change of the read-out :func:`closing_readout` applies, relative to it
#: (Frobenius norms): a finished fit's is a few per cent; beyond this it would be refitting
#: the surface, not correcting it
CLOSING_CHANGE_MAX = 0.2


def closing_readout(surface, target, n=CLOSING_POINTS):
    """The read-out layer and shift that minimise the position term of a fit to an exact map.

    The network is linear in its read-out: ``S(p) = c + s W3 h(p)`` with ``h`` the last
    hidden layer. Given the features training has found, the change ``dW`` of ``W3`` and
    the shift ``t`` of the centre ``c`` that minimise ``mean |S(p) - T(p)|^2`` over the
    sphere's measure are a linear least-squares problem, solved at ``n`` fresh uniform
    sphere points (seeded apart from training and evaluation; the features are well
    conditioned, a condition number of about 1e4 on the paper's shapes). Training cannot
    reach this minimum by itself: its steps are noisy, the network has no output bias,
    and the derivative terms pull the read-out towards their own optimum; the fit ends
    with a drift of its surface along and across itself that the closest-point curvature
    measures (docs/fitting.md, "The closing read-out"). The least squares contains every
    affine map of the output (``t + M S`` is ``W3 -> M W3`` and a shift), so it removes at
    least the drift's constant and linear parts. Where ``dW`` is larger than
    ``CLOSING_CHANGE_MAX`` of ``W3`` (a fit of a few steps, far from its target) it would
    be refitting the surface, not correcting it: ``dW`` is then zero and ``t`` the mean
    residual. Not used for a mesh: the parametrisation of its embedding carries its own
    tangential error, and a mesh fit ends on the distance to the mesh itself.

    Parameters
    ----------
    surface : SphericalNeuralSurface, the fitted surface
    target : an exact target (``evaluate_at(p) -> (q, normals)`` in the normalised frame,
        ``center``, ``scale``)
    n : int, number of sphere points

    Returns
    -------
    dW : (3, width) float array, the change of ``surface.net.W3``; t : (3,) float array, the
    change of ``surface.center`` (the surface's units)

    Examples
    --------
    >>> from sns_np.nn import ResidualMLP
    >>> from sns_np.surface._targets import _ShapeTarget
    >>> S = SphericalNeuralSurface(ResidualMLP(width=16, depth=1, seed=0), scale=2.0)
    >>> D = 0.01 * np.random.default_rng(1).standard_normal(S.net.W3.shape) * S.net.W3.std()
    >>> net = S.net.copy(); net.W3[...] += D       # its read-out changed by 1%, moved along x
    >>> moved = SphericalNeuralSurface(net, center=[0.1, 0.0, 0.0], scale=2.0)
    >>> dW, t = closing_readout(S, _ShapeTarget(moved))
    >>> bool(np.allclose(dW, D, atol=1e-8) and np.allclose(t, [0.1, 0.0, 0.0], atol=1e-8))
    True
    >>> net = S.net.copy(); net.W3[...] *= 1.5                  # a change of 1/2 of W3
    >>> far = SphericalNeuralSurface(net, scale=2.0)
    >>> dW, t = closing_readout(S, _ShapeTarget(far))
    >>> bool(np.array_equal(dW, np.zeros_like(dW)))             # is not a correction
    True
    """
    p = uniform_sphere(n, np.random.default_rng(2**31 - 2))
    q, _ = target.evaluate_at(p)
    net = surface.net
    h = net.features(p).astype(np.float64)                  # S(p) = c + s (W3 h(p) + b3)
    y = surface.center + surface.scale * (h @ net.W3.T + (net.b3 if net.bias else 0.0))
    r = (target.center + target.scale * q - y) / surface.scale
    F = np.hstack([h, np.ones((n, 1))])
    coef = np.linalg.lstsq(F, r, rcond=None)[0]
    dW, t = coef[:-1].T, surface.scale * coef[-1]
    if not np.linalg.norm(dW) <= CLOSING_CHANGE_MAX * np.linalg.norm(net.W3):  # NaN too
        return np.zeros_like(dW), surface.scale * r.mean(axis=0)
    return dW, t


def _evaluate(surface, target, n_eval):
    """Held-out errors at n_eval fixed sphere points (seeded apart from training)."""
    g = np.random.default_rng(2**31 - 1)
    p = uniform_sphere(n_eval, g)
    q, nt = target.evaluate_at(p)
    q = target.center + target.scale * q
    y, J = surface.jet(p, 1)
    JR = tangent_jacobian(J, tangent_frame(p))
    n, _ = normals_from_tangents(JR[:, :, 0], JR[:, :, 1], degenerate="zero")
    err = np.linalg.norm(y - q, axis=1)
    ang = _angle(n, nt)
    report = FitReport(position_mean=float(err.mean()), position_rms=float(np.sqrt((err ** 2)
                       .mean())), position_max=float(err.max()),
                       bbox_diagonal=target.bbox_diagonal, normal_mean_deg=float(ang.mean()),
                       normal_max_deg=float(ang.max()))
    if hasattr(target, "nearest"):      # a mesh: the geometry, whatever the parametrisation
        # means over the surface's area: each point weighted by its area element, so that
        # the way the sphere is spread over the surface does not weight the result
        dA = area_element_from_jets(JR)
        total = dA.sum()
        w = dA / total if np.isfinite(total) and total > 0 else np.full(len(dA), 1 / len(dA))
        face, beta, d = target.nearest().query(y)
        report.distance_mean = float(w @ d)
        report.closest_normal_mean_deg = float(w @ _angle(n, target.corr.to_mesh(face, beta)[1]))
        report.vertex_distance_mean = float(vertex_distances(surface, target.corr.V,
                                                             target.corr.Vs).mean())
    return report


def vertex_distances(surface, X, p, iterations=4):
    """Distances from the points ``X`` (n, 3) to a surface map, each found from the sphere
    point ``p`` (n, 3) given for it (a mesh vertex's own, from the embedding) by Gauss-Newton
    steps on the sphere: the nearest of the surface points met on the way.

    Every point met is a point of the surface, so the result never underestimates the
    distance: a feature the surface skips stays far. Starting from the vertex's own sphere
    point finds parts that an embedding squeezes into a patch too small for a uniform sample
    of the sphere (docs/fitting.md, "Two more held-out meshes").

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> p = uniform_sphere(5, rng=0)
    >>> q = p + 0.3 * np.roll(p, 1, axis=1)
    >>> X = 2.5 * q / np.linalg.norm(q, axis=1, keepdims=True)   # 0.5 off a radius-2 sphere
    >>> bool(np.allclose(vertex_distances(Sphere(2.0), X, p), 0.5))
    True
    """
    X = np.asarray(X, dtype=np.float64)
    p = np.array(p, dtype=np.float64)
    best = np.full(len(X), np.inf)
    for it in range(iterations + 1):
        y, J = surface_jet(surface, p, 1)
        r = X - y
        best = np.minimum(best, np.linalg.norm(r, axis=1))
        if it == iterations:
            break
        R = tangent_frame(p)
        JR = tangent_jacobian(J, R)
        G = np.einsum("kia,kib->kab", JR, JR)
        # a tiny ridge: a degenerate point (S_u x S_v = 0) takes a step, not an error
        G += (1e-12 * np.trace(G, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(2)
        d = np.linalg.solve(G, np.einsum("kia,ki->ka", JR, r)[..., None])[..., 0]
        p = p + np.einsum("kab,kb->ka", R, d)
        p /= np.linalg.norm(p, axis=1, keepdims=True)
    return best


def _angle(a, b):
    """Angles (degrees) between the rows of two arrays of unit vectors."""
    return np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)))
