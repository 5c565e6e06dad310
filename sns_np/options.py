"""The options of the long-running operations, one frozen dataclass each.

FitOptions       fitting a SphericalNeuralSurface (:func:`sns_np.surface.fit_mesh`, ...)
HeatOptions      the heat flow (:func:`sns_np.flows.heat_flow`)
MCFOptions       the mean curvature flow (:func:`sns_np.flows.mean_curvature_flow`)

Each field is one option: its default (``None`` means "auto": the operation chooses it and
says why), its help text and its check live together in the field, so the functions, the
``sns-np`` command and the examples all read them from here and no default is written twice.
A field's ``metadata`` holds ``help`` (one line), ``check`` (an :class:`Int`, :class:`Real`,
:class:`Choice` or :class:`Any`) and ``resume`` (part of the key that a checkpoint must match
to be resumed).

This module is light (NumPy only), so that the command line can build its options from it
without importing the network engine.

Examples
--------
>>> o = FitOptions.from_kwargs(width=64, steps=None)   # None: the default
>>> o.width, o.depth, o.steps
(64, None, None)
>>> FitOptions.help("dtype")
'training precision; the result is float64'
>>> HeatOptions().refit_steps, MCFOptions().lr
(100, 0.0001)
"""

from __future__ import annotations

import argparse
import dataclasses
import numbers
from collections.abc import Mapping
from dataclasses import dataclass

from ._validation import check_choice, check_positive_float, check_positive_int

__all__ = ["FitOptions", "HeatOptions", "MCFOptions", "UnknownOptionError", "add_arguments",
           "given_arguments", "AUTO", "AUTO_EXACT", "DETAIL_RANGE", "NORMAL_DETAIL_RANGE",
           "EXACT_INPUT_SCALE_MAX", "NORMAL_WEIGHT", "JACOBIAN_WEIGHT", "HESSIAN_WEIGHT",
           "SAMPLINGS", "MESH_SMOOTHING", "NORMAL_HEIGHT_TIE", "NORMAL_HEIGHT_LEVELS",
           "NORMAL_HEIGHT_UNKNOWNS", "CREASE_GAP", "CREASE_ANGLE",
           "COARSE_VERTEX_FRACTION", "COARSE_CLOSEST_NORMAL", "AREA_WEIGHT_MAX", "COARSE_TURN",
           "SAMPLE_JITTER", "SAMPLE_VERTEX_FRACTION", "SAMPLE_TANGENT_WEIGHT",
           "RIPPLED_INPUT_SCALE",
           "check_creases", "check_smooth",
           "CHECKPOINT_STEPS", "CHECKPOINT_SECONDS", "SCHEMES", "DEFAULT_SCHEME",
           "DEFAULT_SNAPSHOTS", "HEAT_METHODS"]


class UnknownOptionError(TypeError, ValueError):
    """An option name that the operation does not know (a TypeError, like an unexpected
    keyword argument, and a ValueError, like any other bad option)."""


# ------------------------------------------------------------------------------ checks

class Int:
    """An integer ``>= minimum``."""

    parse = int

    def __init__(self, minimum=1):
        self.minimum = minimum

    def __call__(self, value, name):
        check_positive_int(value, name, self.minimum)


class Real:
    """A finite number ``> 0`` (``>= 0`` with ``allow_zero``)."""

    parse = float

    def __init__(self, allow_zero=False):
        self.allow_zero = allow_zero

    def __call__(self, value, name):
        check_positive_float(value, name, self.allow_zero)


class Fraction:
    """A number in [0, 1]."""

    parse = float

    def __call__(self, value, name):
        if check_positive_float(value, name, allow_zero=True) > 1.0:
            raise ValueError(f"{name} must lie in [0, 1], got {value!r}")


class Angle:
    """An angle in degrees, in [0, 180]."""

    parse = float

    def __call__(self, value, name):
        if check_positive_float(value, name, allow_zero=True) > 180.0:
            raise ValueError(f"{name} must be an angle in degrees in [0, 180], got {value!r}")


class Decay:
    """A number in [0, 1): the decay of a running mean."""

    parse = float

    def __call__(self, value, name):
        if check_positive_float(value, name, allow_zero=True) >= 1.0:
            raise ValueError(f"{name} must lie in [0, 1), got {value!r}")


class AreaFactor:
    """0 (off) or a factor >= 1."""

    parse = float

    def __call__(self, value, name):
        v = check_positive_float(value, name, allow_zero=True)
        if 0.0 < v < 1.0:
            raise ValueError(f"{name} must be 0 (off) or a factor >= 1, got {value!r}")


class Choice:
    """One of a few strings."""

    parse = str

    def __init__(self, *values):
        self.values = values

    def __call__(self, value, name):
        check_choice(value, name, set(self.values))


class Any:
    """Anything: the operation checks it where it uses it (a seed, a dict of options).
    ``parse`` reads it from the command line."""

    def __init__(self, parse=str):
        self.parse = parse

    def __call__(self, value, name):
        pass


def option(default, help, check, resume=False):
    """A dataclass field for one option: its default, one line of help, its check and
    whether it is part of the resume key."""
    return dataclasses.field(default=default,
                             metadata={"help": help, "check": check, "resume": resume})


# ------------------------------------------------------------------------------ base

class Options:
    """What every options dataclass shares: construction from keyword arguments, checks,
    the resume key and the conversion to and from the metadata of model files.

    Examples
    --------
    >>> o = MCFOptions.from_kwargs(lr=1e-3, batch=None)
    >>> o.replace(refit_steps=5).to_dict()["refit_steps"], o.refit_steps   # frozen: a copy
    (5, 100)
    >>> MCFOptions.from_dict({"lr": 1e-3, "mcf_time": 0.5}) == o           # others ignored
    True
    >>> MCFOptions.names()[:3], MCFOptions.help("batch")
    (('n_points', 'refit_steps', 'lr'), 'samples per refit step (default: all points)')
    """

    #: the start of the message naming unknown options ({names} is filled in)
    _unknown = "unknown option(s) {names}"

    def __post_init__(self):
        self.check()

    def check(self):
        """Check every option (a ValueError naming the option and what was expected)."""
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None and f.default is None:        # "auto"
                continue
            f.metadata["check"](value, f.name)

    @classmethod
    def names(cls):
        """The option names, in order."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def field(cls, name):
        """The dataclass field of option ``name``."""
        return next(f for f in dataclasses.fields(cls) if f.name == name)

    @classmethod
    def help(cls, name):
        """The help text of option ``name``."""
        return cls.field(name).metadata["help"]

    @classmethod
    def from_kwargs(cls, **kwargs):
        """The options from keyword arguments; ``None`` means the default, and unknown names
        are refused (:class:`UnknownOptionError`, listing the valid ones)."""
        return cls.split(kwargs)[0]

    @classmethod
    def split(cls, kwargs, extra=()):
        """``(options, rest)``: the options among ``kwargs`` and the names in ``extra``
        (keyword arguments the caller handles itself). Any other name is refused."""
        names = cls.names()
        unknown = sorted(set(kwargs) - set(names) - set(extra))
        if unknown:
            valid = ", ".join(sorted(names)) + (f" or {', '.join(extra)}" if extra else "")
            raise UnknownOptionError(
                cls._unknown.format(names=", ".join(map(repr, unknown)))
                + f"; expected some of {valid}")
        known = {k: v for k, v in kwargs.items() if k in names and v is not None}
        rest = {k: v for k, v in kwargs.items() if k not in names}
        return cls(**known), rest

    def replace(self, **changes):
        """A copy with some options changed (checked again)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self):
        """The options as a dict, in field order (what a model's metadata keeps)."""
        return {name: getattr(self, name) for name in self.names()}

    @classmethod
    def from_dict(cls, d):
        """The options kept in a metadata dict (other keys are ignored)."""
        return cls(**{k: v for k, v in d.items() if k in cls.names() and v is not None})

    def resume_key(self):
        """The options a checkpoint must match to be resumed, as a dict."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if f.metadata["resume"]}


def _is_int(value):
    return isinstance(value, numbers.Integral)


# ------------------------------------------------------------------------------ fit

#: the read-out error of scale-4 features (normalised units, area 4 pi;
#: :func:`sns_np.surface.fit.detail`) at and below which a target is treated as smooth, and at
#: and above which as detailed; in between, the choices are interpolated on a log scale.
#: Measured (docs/fitting.md): spheres and ellipsoids 6e-4 - 3.3e-3; spot, max, the armadillo
#: and the paper's shapes 3e-2 - 1.2e-1
DETAIL_RANGE = (5e-3, 2e-2)

#: the same for the unit normals' read-out error (dimensionless); a target is as detailed as
#: the larger of its two positions says. The position's error grows with the relief's height,
#: the normals' with its slope, so a low relief of short wavelength (FLOWER's ridges at 3%
#: of their height: positions 1.0e-2, between; normals 0.35, detailed) is not taken for a
#: smooth shape. Measured (docs/fitting.md): spheres and ellipsoids 6e-4 - 6.9e-3; the
#: shared detailed meshes and the paper's shapes 0.2 - 0.97
NORMAL_DETAIL_RANGE = (2e-2, 4e-1)

#: the options "auto" chooses at either end of DETAIL_RANGE
AUTO = {
    "smooth": {"input_scale": 4.0, "lr": 1e-4, "warmup": 50, "time_budget": 240.0,
               "batch": 2048, "sampling": "area", "optimizer": "adam", "width": 256,
               "depth": 8, "closest_after": 1.0},
    "detailed": {"input_scale": 40.0, "lr": 4e-3, "warmup": 100, "time_budget": 540.0,
                 "batch": 512, "sampling": "error", "optimizer": "soap", "width": 128,
                 "depth": 8, "closest_after": 0.2},
}

#: where the detailed end differs for an analytic map (``fit_shape``): a wider, shallower
#: network of about the same cost per step (192^2 x 4 against 128^2 x 8 in the products). Its
#: position had stopped improving at 128 x 8 (FLOWER, 1800 s), and at 192 x 4 FLOWER's
#: held-out position is 3.9e-5 against 5.1e-5 - 5.9e-5, its mean H error at the closest point
#: 2.56% against 3.08% - 3.67% (540 s; docs/fitting.md, "The network's width"). A mesh keeps
#: 128 x 8: the armadillo at 192 x 4 ends at 2.78 deg against 2.36 - 2.44. And a longer
#: budget: a detailed map's curvature keeps improving long after a mesh's fit has used what
#: its mesh knows, and FLOWER's mean H error (closest point) is 2.06% at 540 s, 0.89% and
#: 0.83% at 1800 s in two runs (docs/fitting.md, "The paper's shapes")
AUTO_EXACT = {"width": 192, "depth": 4, "time_budget": 1800.0}

#: the fastest first layer "auto" gives an analytic map: its scale is interpolated as a mesh's
#: (4 to 40 over DETAIL_RANGE) and held at this. Its fit supervises the first and second
#: derivatives too, and slower features fit them better, down to a cliff near 7 where FLOWER's
#: fit never leaves its starting plateau (540 s alone, closest-point H error at 40 / 16:
#: FLOWER 2.56 - 2.65% / 2.06%, BOBBLE 0.79 / 0.51%, TREE 0.88 / 0.60%, SPIKE 0.55 / 0.27%;
#: docs/fitting.md, "The first layer's scale for an analytic map"). A cap, not a new end, so
#: a target half way keeps the scale its ridges need (FLOWER at 1% of its relief: 17 -> 16,
#: not 9.6). A mesh keeps 40: it has no derivatives to supervise, and spot's detail wants 40
EXACT_INPUT_SCALE_MAX = 16.0

#: how a fit draws its training points: uniformly by area, or weighted by the recent error
#: with importance weights (a mesh only; ``sns_np.surface._adaptive``)
SAMPLINGS = ("area", "error")

#: the weight of the normal loss that "auto" chooses, by how the target is parametrised: a
#: mesh through its spherical embedding, whose tangential noise the normals steer the fit past
#: (docs/fitting.md, "The normal weight"), or an analytic map (``fit_shape``), whose
#: parametrisation is exact. There, weight 1 lets the normal term dominate and the network
#: buys normals with position (BOBBLE, 1,200 steps: held-out position error 1.39e-2 at weight
#: 1 against 3.66e-3 at 0.1, and H at the closest point 117% against 57%).
NORMAL_WEIGHT = {"embedding": 1.0, "exact": 0.1}

#: the angle (degrees) beyond which a point's normal error counts by its size, not its
#: square (a pseudo-Huber loss, ``position_normal_loss``'s ``normal_huber``), that "auto"
#: chooses, by how the target is parametrised. A mesh's fit is judged by its mean angle, and
#: with the squared loss its points of large error (fingers, ears; targets that disagree)
#: steer it. 540 s, one thread, two fits at once, against the squared loss: armadillo21622
#: normals 2.15 deg against 2.37, distance 3.37e-4 against 3.60e-4; max10606 0.69 against
#: 0.76 deg, decimated_max 1.22 against 1.34, spot 0.76 against 0.74, SPIKE's mesh level
#: (docs/fitting.md, "A robust normal loss"). A coarse mesh keeps the squared loss (BOBBLE's
#: mesh: H 45% against 39%). An analytic map's normals are exact and were not measured with
#: it, nor a warm start (flows, refits): 0, the squared loss.
NORMAL_HUBER = {"embedding": 4.0, "exact": 0.0}

#: the final learning rate of the cosine schedule that "auto" chooses, by how the target is
#: parametrised. An analytic map's targets are exact, and the last steps at a rate ten times
#: lower end nearer them (FLOWER, 540 s: held-out position 6.5e-5 -> 5.1e-5 to 5.9e-5 in three
#: runs, mean H error at the closest point 4.25% -> 3.08% to 3.67%; the other paper shapes'
#: positions 21-31% lower; docs/fitting.md, "The paper's shapes"); a mesh's keep the rate
#: their figures were measured with.
LR_MIN = {"embedding": 1e-5, "exact": 1e-6}

#: SOAP's second-moment decay (Adam's ``b2``, in the eigenbasis of Shampoo's factors) that
#: "auto" chooses, by how the target is parametrised. The second moment is kept by index
#: while the eigenbases turn every 10 steps, and a short memory follows them: on a mesh it
#: learns detail faster (armadillo21622, 540 s: normals 2.11 deg against 2.42, distance
#: 3.45e-4 against 3.62e-4; docs/fitting.md, "SOAP's constants"). An analytic map's
#: curvature wants the long one (BOBBLE's exact map, 540 s on 2026-12-01: H at the closest
#: point 9.9% at 0.999 against 13.1% at 0.95). "auto" leaves Adam its own 0.999.
SECOND_MOMENT_DECAY = {"embedding": 0.95, "exact": 0.999}

#: the normal weight of the nearest-point phase that "auto" chooses: ``CLOSEST_NORMAL_AREA``
#: times the mesh's mean face area (normalised units, total 4 pi), at most
#: ``CLOSEST_NORMAL_MAX``. The term then counts a normal error theta as the position error
#: theta * L it makes across a patch of about 50 faces (L^2 = 50 x the mean face area), so a
#: finer mesh, whose positions carry more of the shape, leans on them more. Measured at 540 s
#: (docs/fitting.md, "The nearest-point phase"): spot (5,856 faces) is best near 0.1 (0.72
#: deg; 0.01 gives 1.37), the armadillo (43,240) near 0.01 (2.29 deg; 0.1 gives 2.79)
CLOSEST_NORMAL_AREA = 50.0
CLOSEST_NORMAL_MAX = 0.1

#: the most by which "auto" lets a training point's weight follow the fitted surface's own
#: area in a mesh's nearest-point phase (``area_weight_max``; ``surface.losses.
#: own_area_weights``). The points are drawn by the mesh's area through the embedding, but the
#: fit is judged over the surface it makes. Where the network stretches a patch of the sphere
#: over more surface than the embedding does, that surface had fewer points than its share.
#: Stein's sword (held out), 540 s, one thread, two fits at once: 7% of its surface lay where
#: the network's area element was over 4 times the mean, with 8.3 degrees of normal error
#: there (35% of the total); weighted, that share fell to 3% at 1.6 degrees, and the mean from
#: 1.60 to 1.15 degrees (docs/fitting.md, "The surface's own area"). Not on a coarse mesh,
#: whose interpolated normals are guesses: there the weights followed those normals at the
#: positions' cost (BOBBLE's level-5 mesh, two pairs: distance 6% worse, exact H 2-4% worse;
#: armadillo1200: distance 4% worse)
AREA_WEIGHT_MAX = 4.0

#: the weight of the Jacobian loss (the derivatives along the sphere, ``losses.jacobian_loss``)
#: that "auto" chooses. An analytic map's derivatives are exact data: matching them puts the
#: first derivatives under direct control and the second ones (curvature) follow (fit_shape,
#: 1,500 steps, H error at the closest point: BOBBLE 19.3% -> 8.3%, FLOWER 161% -> 44%,
#: TREE 54% -> 11%; flat from weight 0.1 to 10; docs/fitting.md, "The Jacobian loss"). A
#: mesh's are those of its piecewise-linear embedding, tangential noise to steer past: 0.
#: 0.1 since session 32 (with the Hessian weight 10 times lower too): at 540 s the position
#: leads more, and the closest-point H error falls (BOBBLE 1.11% -> 1.00%, TREE 1.19% ->
#: 0.99%, with the closing map; docs/fitting.md, "The paper's shapes").
JACOBIAN_WEIGHT = {"embedding": 0.0, "exact": 0.1}

#: the weight of the Hessian loss (the second derivatives along the sphere,
#: ``losses.hessian_loss``) that "auto" chooses. An analytic map's are exact data, and
#: curvature is made of them (fit_shape, 1,500 steps, with the Jacobian loss, H error at the
#: closest point: BOBBLE 8.3% -> 4.1%, FLOWER 44% -> 17%, TREE 11.5% -> 3.8%; BOBBLE at weight
#: 1e-4 / 1e-2 / 1e-1: 4.8%, 12.9%, 33%: larger weights cost position; docs/fitting.md, "The
#: Hessian loss"). A step costs about twice as much; with the same 540 s: TREE 3.4% -> 1.75%,
#: FLOWER 10.1% -> 6.9%, SPIKE 0.83% -> 0.57%, BOBBLE 2.6% -> 2.3%. A mesh's embedding is
#: piecewise linear: 0. 1e-4 since session 32, with the Jacobian weight (above).
HESSIAN_WEIGHT = {"embedding": 0.0, "exact": 1e-4}

#: checkpoint cadence of a fit (``checkpoint_every`` steps, ``checkpoint_seconds`` seconds,
#: whichever comes first): a crash loses at most about a minute
CHECKPOINT_STEPS = 500
CHECKPOINT_SECONDS = 60.0

#: position targets of a mesh fit (``fit_mesh(smooth=...)``), the default first: "phong" the
#: Phong-tessellated mesh, "normals" the surface over the mesh whose normals follow its
#: interpolated vertex normals (:class:`sns_np.mesh.NormalHeights`; spot 0.72 -> 0.54 deg,
#: the others level, SPIKE's mesh worse against its truth: not the default, docs/fitting.md,
#: "The mesh's normals as a target"), "none" its flat triangles
MESH_SMOOTHING = ("phong", "normals", "none")

#: the "normals" target's tie to the mesh's vertices (:class:`sns_np.mesh.NormalHeights`):
#: the surface at 3e-2 is about as near the mesh as the 540-s fit and its normals nearer the
#: mesh's (spot 4.9e-4 of the diagonal / 0.66 deg, the armadillo 2.8e-4 / 1.30); on a mesh
#: of an ellipsoid it is 6 times nearer the ellipsoid than the triangles. 1e-3 follows the
#: normals more closely, 1 the vertices (nearer the truth on SPIKE's mesh)
NORMAL_HEIGHT_TIE = 3e-2

#: the "normals" target's heights are piecewise linear on the mesh's midpoint subdivision:
#: as many rounds (at most ``NORMAL_HEIGHT_LEVELS``) as keep its vertices within
#: ``NORMAL_HEIGHT_UNKNOWNS`` (spot 3 rounds, 187,394 unknowns, 4 s; the armadillo 2 rounds,
#: 345,634, 7 s)
NORMAL_HEIGHT_LEVELS = 3
NORMAL_HEIGHT_UNKNOWNS = 400_000

#: a coarse mesh, too coarse for its interpolated targets (the Phong points and the blended
#: vertex normals) to be followed between its vertices: its Phong tessellation stands off
#: its flat triangles by more than ``CREASE_GAP`` of the bounding-box diagonal on average
#: (coarse for its size), or its vertex normals turn by more than ``COARSE_TURN`` degrees
#: across a median edge (coarse for its curvature: BOBBLE's ripples on a 10,242-vertex
#: icosphere turn them by 31 degrees, the armadillo's 21,622 vertices by 12). Measured by
#: ``sns_np.surface._targets.coarseness`` (docs/fitting.md, "Coarse meshes")
CREASE_GAP = 1e-3
COARSE_TURN = 20.0

#: creases of a mesh fit (``fit_mesh(creases=...)``): with "auto", a coarse mesh keeps the
#: two sides of every edge sharper than ``CREASE_ANGLE`` degrees apart; finer meshes
#: interpolate their vertex normals everywhere (docs/fitting.md, "Meshes with sharp edges")
CREASE_ANGLE = 60.0

#: a coarse mesh is fitted to its vertices more than to its interpolated targets: that share
#: of each batch is drawn at its vertices, where its positions are exact, and the normal
#: weight of the nearest-point phase is ``COARSE_CLOSEST_NORMAL`` (its interpolated normals
#: are guesses no surface through its vertices follows). Measured on spot qslim-ed to 1,000
#: vertices at 540 s (docs/fitting.md, "Coarse meshes"): distance to the mesh 7.96e-4 of
#: the diagonal against 1.57e-3, and against the fine spot 7.9e-4 / 1.95 deg against
#: 1.60e-3 / 2.40; on BOBBLE's level-5 mesh, errors against the exact shape 6.9 deg / 35% /
#: 68% (normal / H / K) against 12.4 deg / 53% / 111%. A finer mesh samples its faces only
COARSE_VERTEX_FRACTION = 0.25
COARSE_CLOSEST_NORMAL = 0.01

#: a fine sample of a smooth surface: a mesh that is not coarse and whose mean curvature
#: changes from a vertex to its neighbours by at most ``SAMPLE_JITTER`` of its size on
#: average (``sns_np.mesh.curvature_jitter``; SPIKE at icosphere level 5 0.072, the demo's
#: ellipsoid 0.004, against 0.23-0.72 on every scan and sculpture measured and 0.7-1.3 on
#: meshed CAD parts). Its vertices are then the data and its interpolated normals only an
#: estimate (on SPIKE's mesh 1.1 degrees from the truth; interpolating even the exact vertex
#: normals costs 0.52): the fit takes positions only, ``SAMPLE_VERTEX_FRACTION`` of each
#: batch at the vertices and the rest at the Phong points, no normal loss, no nearest-point
#: phase, and the tangential part of the position error weighted ``SAMPLE_TANGENT_WEIGHT``
#: (the embedding's parameters of the points are piecewise linear; the surface need not
#: follow them). Only for a detailed target: a smooth one (the demo's ellipsoid, 0.004) is
#: fitted faster with its normals. On SPIKE's mesh, 540 s alone: 0.118 deg / 1.46% / 1.98%
#: against the exact normals, H and K, where the normal-following fit gave 0.694 / 3.87% /
#: 8.27% and libigl 0.64 / 5.7% / 10.3% (docs/fitting.md, "A fine sample of a smooth
#: surface, by default")
SAMPLE_JITTER = 0.15
SAMPLE_VERTEX_FRACTION = 0.5
SAMPLE_TANGENT_WEIGHT = 0.01

#: a mesh coarse for its curvature alone (its normals turn by more than ``COARSE_TURN``
#: degrees across a median edge, its Phong tessellation within ``CREASE_GAP`` of its
#: triangles: ripples a few edges wide, like BOBBLE's at icosphere level 5) is fitted by its
#: positions as a fine sample is, its first layer's scale at most ``RIPPLED_INPUT_SCALE``
#: (an analytic map's cap, ``EXACT_INPUT_SCALE_MAX``): sampled by the vertices alone, the
#: ripples pin down no finer features. BOBBLE's mesh, one-thread pairs at 540 s: 2.64 deg /
#: 19.6% / 26.6% against its exact normals, H and K at scale 16, 3.58 / 31.1% / 43.5% at 40,
#: about 7.0 / 39% / 74% with the coarse mesh's normal-following defaults; libigl 6.04 /
#: 42.1% / 74.4% (docs/fitting.md, "A fine sample of a smooth surface, by default")
RIPPLED_INPUT_SCALE = 16.0


def check_creases(creases):
    """``creases`` of :func:`~sns_np.surface.fit_mesh` checked: "auto", "none" or an angle in
    degrees in (0, 180] (returned as a float); raises ValueError naming what was expected.

    Examples
    --------
    >>> check_creases("auto"), check_creases(45)
    ('auto', 45.0)
    """
    if isinstance(creases, str):
        if creases in ("auto", "none"):
            return creases
    elif isinstance(creases, numbers.Real) and not isinstance(creases, bool) and \
            0.0 < float(creases) <= 180.0:
        return float(creases)
    raise ValueError(f"creases must be 'auto', 'none' or an angle in degrees in (0, 180], "
                     f"got {creases!r}")


def check_smooth(smooth, creases="auto"):
    """``smooth`` and ``creases`` of :func:`~sns_np.surface.fit_mesh` checked together:
    ``smooth`` one of ``MESH_SMOOTHING``, and not "normals" with a crease angle (its surface
    follows the vertex normals across every edge, so it has no creases to keep); returns
    ``(smooth, creases)`` (``creases`` as :func:`check_creases`); raises ValueError naming
    what was expected.

    Examples
    --------
    >>> check_smooth("normals"), check_smooth("phong", 45)
    (('normals', 'auto'), ('phong', 45.0))
    >>> check_smooth("normals", 45)                  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: smooth='normals' follows the vertex normals across every edge and keeps ...
    """
    check_choice(smooth, "smooth", MESH_SMOOTHING)
    creases = check_creases(creases)
    if smooth == "normals" and not isinstance(creases, str):
        raise ValueError(f"smooth='normals' follows the vertex normals across every edge and "
                         f"keeps no creases; with creases={creases!r} pass smooth='phong' or "
                         f"'none' (or creases='auto' or 'none')")
    return smooth, creases


def _auto(name, unit=""):
    """How "auto" chooses option ``name``, with the values at either end (for help texts)."""
    s, d = AUTO["smooth"][name], AUTO["detailed"][name]
    fmt = "" if isinstance(s, str) else "g"
    exact = (f", {AUTO_EXACT[name]:{fmt}}{unit} for a detailed analytic map"
             if name in AUTO_EXACT else "")
    return (f"chosen from the target's detail, {s:{fmt}}{unit} for a smooth target, "
            f"{d:{fmt}}{unit} for a detailed one{exact}")


@dataclass(frozen=True)
class FitOptions(Options):
    """The options of a fit (:func:`sns_np.surface.fit_mesh`, :func:`~sns_np.surface.fit_shape`,
    :func:`~sns_np.surface.fit_sampler`); docs/fitting.md explains and measures each choice.

    ``None`` means "auto": the fit chooses the value from the target's detail and reports the
    choice and its reason (``FitReport.choices``).

    Examples
    --------
    >>> o = FitOptions(width=32, depth=2, steps=100)
    >>> o.lr is None, o.to_dict()["schedule"]            # lr: chosen by the fit
    (True, 'cosine')
    >>> FitOptions.from_dict(o.to_dict()) == o           # as kept in a model's metadata
    True
    >>> FitOptions(steps=0)
    Traceback (most recent call last):
    ...
    ValueError: steps must be an integer >= 1, got 0
    >>> FitOptions.from_kwargs(widht=32)
    Traceback (most recent call last):
    ...
    sns_np.options.UnknownOptionError: unknown fitting option(s) 'widht'; expected some of ...
    """

    _unknown = "unknown fitting option(s) {names}"

    width: int | None = option(None, f"network width of a fresh network (default: "
                               f"{_auto('width')})", Int(1), resume=True)
    depth: int | None = option(None, f"residual blocks of a fresh network (default: "
                               f"{AUTO['detailed']['depth']}; {AUTO_EXACT['depth']} for a "
                               f"detailed analytic map, interpolated in between)", Int(0),
                               resume=True)
    steps: int | None = option(
        None, "step budget (default: as many as fit the time budget, with the learning rate "
        "decaying with the time elapsed)", Int(1), resume=True)
    batch: int | None = option(None, f"fresh samples per step (default: {_auto('batch')})",
                               Int(1), resume=True)
    lr: float | None = option(None, f"peak learning rate (default: {_auto('lr')})", Real(),
                              resume=True)
    lr_min: float | None = option(
        None, f"final learning rate of the cosine schedule (default: {LR_MIN['embedding']:g} "
        f"for a mesh, {LR_MIN['exact']:g} for an analytic map)", Real(allow_zero=True),
        resume=True)
    second_moment_decay: float | None = option(
        None, f"second-moment decay of Adam and SOAP (default for SOAP: "
        f"{SECOND_MOMENT_DECAY['embedding']:g} for a mesh, {SECOND_MOMENT_DECAY['exact']:g} "
        f"for an analytic map; Adam's own 0.999)", Decay(), resume=True)
    optimizer: str | None = option(
        None, f"optimiser; soap: Adam in the eigenbasis of Shampoo's factors for the hidden "
        f"matrices (default: {_auto('optimizer')})", Choice("adam", "rmsprop", "sgd", "soap"),
        resume=True)
    schedule: str = option("cosine", "learning-rate schedule", Choice("constant", "cosine"),
                           resume=True)
    warmup: int | None = option(None, f"steps of linear learning-rate warm-up "
                                f"(default: {_auto('warmup')})", Int(0), resume=True)
    sampling: str | None = option(
        None, f"how training points are drawn: uniformly by area, or weighted by the recent "
        f"error with importance weights, the same objective (default: "
        f"{_auto('sampling')})", Choice(*SAMPLINGS), resume=True)
    vertex_fraction: float | None = option(
        None, "share of each batch drawn at the mesh's vertices, whose positions are the "
        f"mesh's only exact data (a mesh only; default: {COARSE_VERTEX_FRACTION:g} on a "
        f"coarse mesh, {SAMPLE_VERTEX_FRACTION:g} on a mesh whose vertices sample a smooth "
        f"surface, 0 otherwise)", Fraction(), resume=True)
    normal_weight: float | None = option(
        None, f"weight of the normal loss (default: {NORMAL_WEIGHT['embedding']:g} for a mesh, "
        f"0 for a mesh whose vertices sample a smooth surface, whose interpolated normals are "
        f"only an estimate, {NORMAL_WEIGHT['exact']:g} for an analytic map, whose "
        f"parametrisation is exact)",
        Real(allow_zero=True), resume=True)
    normal_huber: float | None = option(
        None, f"angle in degrees beyond which a point's normal error counts by its size, not "
        f"its square (a pseudo-Huber loss; 0: squared throughout; default: "
        f"{NORMAL_HUBER['embedding']:g} for a mesh, {NORMAL_HUBER['exact']:g} for a coarse "
        f"mesh, an analytic map or a warm start)", Angle(), resume=True)
    jacobian_weight: float | None = option(
        None, f"weight of the loss on the derivatives along the sphere (default: "
        f"{JACOBIAN_WEIGHT['exact']:g} for an analytic map, whose derivatives are exact; a "
        f"mesh only takes 0)", Real(allow_zero=True), resume=True)
    hessian_weight: float | None = option(
        None, f"weight of the loss on the second derivatives along the sphere (default: "
        f"{HESSIAN_WEIGHT['exact']:g} for an analytic map, whose derivatives are exact; a "
        f"mesh only takes 0)", Real(allow_zero=True), resume=True)
    dtype: str = option("float32", "training precision; the result is float64",
                        Choice("float32", "float64"), resume=True)
    init: str = option("ridge", "output layer of a fresh network: the least-squares read-out "
                       "of its initial features, or random", Choice("ridge", "random"),
                       resume=True)
    input_scale: float | None = option(
        None, f"scale of the first layer's initial weights (default: "
        f"{_auto('input_scale')}, interpolated in between; at most "
        f"{EXACT_INPUT_SCALE_MAX:g} for an analytic map)", Real(), resume=True)
    tangent_weight: float | None = option(
        None, f"weight of the tangential part of the position error (default: "
        f"{SAMPLE_TANGENT_WEIGHT:g} on a mesh whose vertices sample a smooth surface, 1 "
        f"otherwise)", Real(), resume=True)
    closest_after: float | None = option(
        None, f"fraction of the fit after which positions and normals are compared at the "
        f"mesh point nearest each network point, not at the embedding's correspondence (1: "
        f"never; a mesh only; default: {_auto('closest_after')}; 1 on a mesh whose vertices "
        f"sample a smooth surface)", Fraction(), resume=True)
    closest_normal_weight: float | None = option(
        None, f"weight of the normal loss while targets are the nearest mesh points "
        f"(default: {CLOSEST_NORMAL_AREA:g} x the mean face area in normalised units, at most "
        f"{CLOSEST_NORMAL_MAX:g}: a finer mesh leans more on its positions; "
        f"{COARSE_CLOSEST_NORMAL:g} on a coarse mesh, whose interpolated normals are guesses; "
        f"0 with normal_weight 0, which computes no derivatives)",
        Real(allow_zero=True), resume=True)
    anchor_weight: float = option(
        1.0, "weight of the correspondence's position error while targets are the nearest "
        "mesh points (it keeps the parametrisation from drifting)", Real(allow_zero=True),
        resume=True)
    area_weight_max: float | None = option(
        None, f"in a mesh's nearest-point phase, weight each point by the fitted surface's "
        f"area element over the embedding's, clipped to [1/this, this] (0: the embedding's "
        f"measure; default: {AREA_WEIGHT_MAX:g} when the phase runs on a fine mesh, else 0)",
        AreaFactor(),
        resume=True)
    readout_every: int = option(0, "refit the output layer every this many steps (0: never)",
                                Int(0), resume=True)
    readout: str = option("gn", "how the output layer is refitted: Levenberg-Marquardt on the "
                          "whole loss, or least squares on the positions",
                          Choice("gn", "ridge"), resume=True)
    time_budget: float | None = option(
        None, f"seconds of fitting, checked every step (default when steps is not given either: "
        f"{_auto('time_budget', ' s')}, in all)", Real())
    tol: float | None = option(None, "stop when the running RMS position error, relative to "
                               "the normalised size, is below this", Real())
    n_eval: int = option(20000, "held-out sphere points of the report", Int(1))
    seed: object = option(0, "random seed of initialisation and sampling",
                          Any(parse=int), resume=True)

    def resume_key(self):
        """The options a checkpoint must match; a Generator seed matches any other.

        Examples
        --------
        >>> key = FitOptions(seed=3).resume_key()
        >>> key["seed"], "time_budget" in key           # a resumed fit may get more time
        (3, False)
        """
        key = super().resume_key()
        key["seed"] = self.seed if _is_int(self.seed) else "generator"
        return key


# ------------------------------------------------------------------------------ flows

#: explicit time schemes of the network flows: name -> ``(a, b)`` of the two-stage
#: Runge-Kutta step ``y* = y + a h F(y)``, ``y+ = y + h ((1 - b) F(y) + b F(y*))``
#: (``None``: one stage, forward Euler, the paper's). ``a b = 1/2`` makes both second order.
SCHEMES = {"heun": (1.0, 0.5), "midpoint": (0.5, 1.0), "euler": None}
DEFAULT_SCHEME = "heun"

#: the methods of the heat flow, default first: explicit steps of a network, or exact in time
#: through eigenmodes
HEAT_METHODS = ("network", "spectral")

#: snapshots after t = 0 of a flow given no snapshot times (``n_snapshots=``)
DEFAULT_SNAPSHOTS = 10

@dataclass(frozen=True)
class HeatOptions(Options):
    """The options of :func:`sns_np.flows.heat_flow` (docs/flows.md measures them).

    The network scheme uses ``width`` to ``growth``, the spectral scheme ``k``, ``n_quad``
    and ``eigen_options``.

    Examples
    --------
    >>> HeatOptions(refit_steps=20).to_dict()["refit_steps"]
    20
    >>> HeatOptions(growth=1.0)
    Traceback (most recent call last):
    ...
    ValueError: growth must be > 1, got 1.0
    """

    _unknown = "unknown option(s) {names} of heat_flow"

    width: int = option(10, "width of the field network (ignored for a NeuralField, which "
                        "is copied)", Int(1))
    depth: int = option(2, "residual blocks of the field network", Int(0))
    n_points: int | None = option(
        None, "fixed sample points of the network scheme (default: A / (2 pi dt), at the "
        "stability limit, clipped to [64, 10242])", Int(16))
    refit_steps: int = option(100, "Adam steps per refit (a time step has one refit with "
                              "euler, two with heun or midpoint)", Int(0))
    lr: float = option(1e-3, "learning rate of the refits", Real())
    init_steps: int = option(2000, "steps of the initial fit of a field that is not a "
                             "NeuralField", Int(0))
    growth: float = option(2.0, "divergence when max |f - mean| exceeds this times its "
                           "initial value", Real())
    k: int = option(50, "non-constant eigenmodes of the spectral scheme", Int(1))
    n_quad: int = option(20000, "quadrature nodes of the spectral projection", Int(1))
    eigen_options: Mapping | None = option(
        None, "options of sns_np.spectral.eigenmodes for the spectral scheme (a dict)", Any())

    def check(self):
        """Every option's check, and ``growth > 1`` (a flow whose range may not grow at all
        would stop at the first rounding error).

        Examples
        --------
        >>> HeatOptions(growth=3.0).check()                  # silent when all is well
        """
        super().check()
        if self.growth <= 1.0:
            raise ValueError(f"growth must be > 1, got {self.growth}")
        if self.eigen_options is not None and not isinstance(self.eigen_options, Mapping):
            raise ValueError(f"eigen_options must be a dict of options of "
                             f"sns_np.spectral.eigenmodes, got {self.eigen_options!r}")


@dataclass(frozen=True)
class MCFOptions(Options):
    """The options of :func:`sns_np.flows.mean_curvature_flow`: its samples and the refits of
    the surface network (docs/flows.md measures them).

    Examples
    --------
    >>> o = MCFOptions.from_kwargs(refit_steps=10)
    >>> o.refit_steps, o.lr, o.dtype
    (10, 0.0001, 'float64')
    """

    _unknown = "unknown option(s) {names} of mean_curvature_flow"

    n_points: int | None = option(
        None, "sample points per step (default: A / (4 pi dt), clipped to [64, 10242]: the "
        "stability limit holds until the area has halved)", Int(16))
    refit_steps: int = option(100, "optimiser steps per refit (the paper's 'up to 100 "
                              "epochs'; 0 keeps only the read-out solve; a time step has one "
                              "refit with euler, two with heun or midpoint)", Int(0))
    lr: float = option(1e-4, "refit learning rate (Adam, constant)", Real())
    batch: int | None = option(None, "samples per refit step (default: all points)", Int(1))
    normal_weight: float = option(0.0, "weight of the normal loss of the refits (the targets' "
                                  "normals are known only to O(dt))", Real(allow_zero=True))
    dtype: str = option("float64", "precision of the refits", Choice("float32", "float64"))
    growth: float = option(1.5, "divergence when the area exceeds this times the initial "
                           "area", Real())
    n_eval: int = option(256, "held-out points per refit report", Int(1))


# ------------------------------------------------------------------------------ command lines

#: metavars of options whose unit the flag should show
METAVARS = {"time_budget": "SECONDS"}


def _argument_type(name, check):
    """An argparse type for option ``name``: parse the text, then apply the option's own
    check, so that a command line refuses what the library refuses, with its message."""
    what = "an integer" if check.parse is int else "a number"

    def parse(text):
        try:
            value = check.parse(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            check(value, name)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return value
    parse.__name__ = check.parse.__name__      # what argparse names in its own messages
    return parse


def add_arguments(parser, options, names, flags=None):
    """Add one command-line option per field ``names`` of an options dataclass.

    The flag is ``--<name>`` with dashes (or ``flags[name]``); a value is parsed and checked
    as the option's own check does (same message); the help is the field's, with the
    dataclass's default. An option left out stays ``None``, so the library applies its
    default: the command line never writes one down. ``sns-np`` and the examples use it.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    options : an options dataclass (FitOptions, HeatOptions, MCFOptions)
    names : sequence of str, the fields to offer, in help order
    flags : dict, optional, ``{name: flag}`` for flags that differ from the name

    Examples
    --------
    >>> p = argparse.ArgumentParser(prog="fit")
    >>> add_arguments(p, FitOptions, ["width", "time_budget", "optimizer"])
    >>> args = p.parse_args(["--width", "64"])
    >>> args.width, args.time_budget, given_arguments(args, ["width", "time_budget"])
    (64, None, {'width': 64})
    >>> "256 for a smooth target, 128 for a detailed one" in " ".join(p.format_help().split())
    True
    """
    flags = flags or {}
    for name in names:
        f = options.field(name)
        check = f.metadata["check"]
        text = f.metadata["help"] + ("" if f.default is None else f" (default: {f.default})")
        flag = flags.get(name, "--" + name.replace("_", "-"))
        kwargs = {"dest": name, "help": text.replace("%", "%%")}
        if isinstance(check, Choice):
            kwargs["choices"] = check.values
        else:
            kwargs["type"] = _argument_type(name, check)
            kwargs["metavar"] = METAVARS.get(name, flag.lstrip("-").replace("-", "_").upper())
        parser.add_argument(flag, **kwargs)


def given_arguments(args, names):
    """The options among ``names`` given on a parsed command line, as keyword arguments
    (those left out are not passed, so they keep the library's defaults).

    Examples
    --------
    >>> given_arguments(argparse.Namespace(steps=5, lr=None), ["steps", "lr", "batch"])
    {'steps': 5}
    """
    return {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}
