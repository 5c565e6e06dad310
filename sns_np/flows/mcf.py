"""Mean curvature flow ``X_t = Delta_S X = -2 H n`` of a SphericalNeuralSurface (paper Sec. 6).

The state of the flow is the surface map ``S`` (the network). One *refit* moves it to targets:

1. at ``N`` sphere points ``p_i`` (a Fibonacci lattice under a fresh random rotation, drawn once
   per time step) the targets ``q_i`` are given (below);
2. the surface network is refitted from its current weights: an exact least-squares solve of
   the read-out layer, ``refit_steps`` steps of :func:`sns_np.surface.fit_sampler` on the
   pairs ``(p_i, q_i)``, and the read-out solve again.

With the velocity ``V(S)(p) = -2 H n`` at ``S(p)`` (``Delta_S x = -2 H n``, paper Eq. 17;
:func:`sns_np.geometry.differential_quantities`), a step of length ``h`` is

``scheme="euler"`` (the paper's, one refit)
    ``S+ = S + h V(S)``;
``scheme="heun"`` (default, two refits)
    ``S* = S + h V(S)``, then ``S+ = S + h/2 (V(S) + V(S*))``;
``scheme="midpoint"`` (two refits)
    ``S* = S + h/2 V(S)``, then ``S+ = S + h V(S*)``.

Both stages use the same points ``p_i``: ``V(S*)`` is evaluated at the same sphere points on the
refitted stage surface, and the second target adds to the positions ``S(p_i)`` of the step's
start. The two-stage schemes are then the explicit second-order Runge-Kutta methods of the
ODE ``dS/dt = V(S)`` for the map (docs/flows.md measures the order).

The read-out solve is a Gauss-Newton step in the last layer (the network is linear in it): it
moves the surface by the best displacement the current features can express, so the refit
does not lag behind the flow (a uniform shrink, the sphere's flow, is captured exactly).

Every scheme is stable for ``dt <= h_s^2 / (2 pi) = A / (2 pi N)`` (the heat-equation limit
of :mod:`sns_np.flows.heat`, with the current area ``A``; Euler and the two-stage schemes share
the real stability interval ``dt lambda <= 2``); the flow checks it at the start
(``stability=``) and warns once if the shrinking area makes a later step exceed it.

References
----------
T. Williamson and N. J. Mitra, "Neural Geometry Processing via Spherical Neural Surfaces",
Eurographics 2025, Sec. 6.
E. Hairer, S. P. Norsett and G. Wanner, "Solving Ordinary Differential Equations I", Sec. II.1
(explicit Runge-Kutta methods of order 2).
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .._progress import Progress
from .._validation import as_generator, check_choice
from .._validation import check_positive_int as _pos_int
from ..errors import DegenerateMapError, DivergenceError
from ..geometry import area_element, differential_quantities
from ..options import DEFAULT_SNAPSHOTS, MCFOptions
from ..surface import SphericalNeuralSurface, fit_sampler
from ._common import (
    DEFAULT_SCHEME,
    SCHEMES,
    STABILITY_MODES,
    StabilityWarning,
    check_scheme,
    check_stability,
    check_times,
    default_points,
    stability_limit,
    step_points,
    substeps,
)

__all__ = ["mean_curvature_flow", "MeanCurvatureFlowResult", "MCFOptions", "MCF_DEFAULTS"]

#: the default options as a dict (kept for older code: :class:`MCFOptions` holds them)
MCF_DEFAULTS = MCFOptions().to_dict()


@dataclass
class MeanCurvatureFlowResult:
    """Snapshots of a mean curvature flow.

    Attributes
    ----------
    times : (m,) float array, ascending, ``times[0] == 0``
    surfaces : list of m SphericalNeuralSurface, ``surfaces[j]`` at ``times[j]``
    areas : (m,) float array, surface areas (quadrature) of the snapshots
    meshes : list of (V, F, data) per snapshot when ``mesh_level`` was given, else None
    stability_limit : float, ``A / (2 pi N)`` at the start
    steps : int
    seconds : float
    stopped : str, "t_end" or the divergence message
    info : dict, the ``scheme``, the number of ``refits`` (one per step for Euler, two for
        the second-order schemes), their errors (``refit_rms``, input units), sample size,
        options

    Examples
    --------
    What :func:`mean_curvature_flow` returns (its example runs a flow); by hand, with two
    unfitted surfaces standing in for the snapshots:

    >>> from sns_np.nn import ResidualMLP
    >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0))
    >>> res = MeanCurvatureFlowResult(times=np.array([0.0, 0.01]), surfaces=[S, S],
    ...                               areas=np.array([12.57, 12.07]))
    >>> len(res), res.times.tolist(), res.stopped
    (2, [0.0, 0.01], 't_end')
    """

    times: np.ndarray
    surfaces: list
    areas: np.ndarray
    meshes: list | None = None
    stability_limit: float = math.nan
    steps: int = 0
    seconds: float = 0.0
    stopped: str = "t_end"
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.times)

    def save(self, folder, level: int = 5, models: bool = True, overwrite: bool = False):
        """Write ``mcf_000.ply`` ... (meshes with normal, H, K per vertex), the models
        ``mcf_000.npz`` ... (``models=True``) and ``flow.json``, into ``folder`` atomically.

        Examples
        --------
        >>> import os
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0))
        >>> res = MeanCurvatureFlowResult(times=np.array([0.0, 0.01]), surfaces=[S, S],
        ...                               areas=np.array([12.57, 12.07]))
        >>> sorted(os.listdir(res.save("mcf_out", level=1)))
        ['flow.json', 'mcf_000.npz', 'mcf_000.ply', 'mcf_001.npz', 'mcf_001.ply']
        """
        from ..mesh import write_mesh
        from ._common import atomic_folder

        def write(tmp):
            for j, S in enumerate(self.surfaces):
                V, F, data = S.to_mesh(level)
                data = {k: data[k] for k in ("normal", "H", "K", "area_element")}
                write_mesh(tmp / f"mcf_{j:03d}.ply", V, F, data)
                if models:
                    S.save(tmp / f"mcf_{j:03d}.npz")
            (tmp / "flow.json").write_text(json.dumps(self.summary_dict(), indent=1))
        return atomic_folder(folder, write, overwrite)

    def summary_dict(self) -> dict:
        """Times, areas, steps, refits, scheme, timing, stop reason and sample size as a
        JSON-ready dict (what ``flow.json`` holds).

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0))
        >>> res = MeanCurvatureFlowResult(times=np.array([0.0, 0.01]), surfaces=[S, S],
        ...                               areas=np.array([12.57, 12.07]), steps=1,
        ...                               info={"n_points": 128})
        >>> d = res.summary_dict()
        >>> d["flow"], d["steps"], d["n_points"], d["areas"]
        ('mean_curvature', 1, 128, [12.57, 12.07])
        """
        return {"flow": "mean_curvature", "times": [float(t) for t in self.times],
                "areas": [float(a) for a in self.areas], "steps": self.steps,
                "seconds": self.seconds, "stopped": self.stopped,
                "stability_limit": self.stability_limit,
                "scheme": self.info.get("scheme"), "refits": self.info.get("refits"),
                "n_points": self.info.get("n_points")}


class _StepTarget:
    """The targets of one refit, ``q = x + sum_j c_j v_j`` with ``x = S(p)`` of the step's start
    surface and ``v_j = -2 H_j n_j`` the velocities of its stage surfaces, in the surface's
    normalised frame."""

    def __init__(self, S, p, q, normals, stages):
        self.S, self.p = S, p
        self.center, self.scale = S.center, S.scale
        self.q = (q - S.center) / S.scale
        self.normals = normals
        self.bbox_diagonal = float(np.linalg.norm(q.max(axis=0) - q.min(axis=0)))
        self.fingerprint = "mcf-step"
        self.stages = stages  # [(surface, c_j)]

    def sample(self, n, rng):
        N = self.p.shape[0]
        idx = rng.permutation(N) if n >= N else rng.choice(N, n, replace=False)
        return self.p[idx], self.q[idx], self.normals[idx]

    def evaluate_at(self, p):
        q = self.S.jet(p, 0)
        for surface, c in self.stages:
            dq = differential_quantities(surface, p)
            q = q - 2.0 * c * dq.H[:, None] * dq.n
        return (q - self.center) / self.scale, dq.n


def _area(S, n_quad=4096):
    from ..sampling import surface_sample
    return surface_sample(S, n_quad, "quadrature").area


def mean_curvature_flow(surface, t_end, dt, *, scheme: str = DEFAULT_SCHEME, times=None,
                        n_snapshots: int = DEFAULT_SNAPSHOTS, stability: str = "warn",
                        mesh_level: int | None = None, rng=None, progress: bool = False,
                        **options) -> MeanCurvatureFlowResult:
    """Evolve a fitted surface by mean curvature flow ``X_t = Delta_S X = -2 H n``.

    A sphere of radius ``r0`` follows ``r^2 = r0^2 - 4 t``; convex surfaces become round;
    the area decreases (``dA/dt = -4 integral H^2 dA``).

    Parameters
    ----------
    surface : SphericalNeuralSurface (not modified)
    t_end : float > 0
    dt : float > 0, the time step
    scheme : {"heun", "midpoint", "euler"}, the time scheme: "heun" (default) and "midpoint"
        are second order with two refits per step, "euler" is the paper's first-order step
        with one refit (module docstring, docs/flows.md)
    times : sequence of floats in [0, t_end], optional, snapshot times (0 and ``t_end`` always
        included); default ``n_snapshots + 1`` equally spaced times
    stability : {"warn", "raise", "ignore"}, when ``dt`` exceeds ``A / (2 pi N)`` at the start
        (the limit of every scheme)
    mesh_level : int, optional, also keep ``S.to_mesh(mesh_level)`` of every snapshot
    rng : None, int or Generator (sample points and refit batches; ``None`` means 0)
    progress : bool, a progress line on stderr
    **options
        The fields of :class:`MCFOptions` (their defaults and help are there), checked before
        any work: ``n_points`` (samples per step; by default the stability limit holds until
        the area has halved), ``refit_steps`` (the paper's "up to 100 epochs"; 0 keeps only
        the read-out solve), ``lr`` (Adam, constant), ``batch`` (default all points),
        ``normal_weight`` (the targets' normals are known only to O(dt)), ``dtype``,
        ``growth`` (divergence when the area exceeds ``growth`` times the initial area),
        ``n_eval`` (held-out points per refit report).

    Returns
    -------
    MeanCurvatureFlowResult
        ``info["refits"]`` counts the refits (the cost unit: ``steps`` for Euler, twice that
        for the two-stage schemes); ``info["refit_rms"]`` lists their errors.

    Raises
    ------
    ValueError
        Bad options (an unknown ``scheme`` is named with the allowed ones), or ``dt`` beyond
        the stability limit with ``stability="raise"``.
    DivergenceError
        A refit diverged (non-finite values, a degenerate map, a growing area);
        ``exc.result`` holds the snapshots up to the last good surface.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> from sns_np.surface import fit_shape
    >>> S, _ = fit_shape(Sphere(), width=16, depth=1, steps=100, batch=256, progress=False)
    >>> res = mean_curvature_flow(S, 0.02, 0.01, refit_steps=10, n_points=256, rng=0,
    ...                           n_snapshots=2, stability="ignore")
    >>> ratio = res.areas / res.areas[0]                  # a sphere: A(t) = A(0) (1 - 4 t)
    >>> ratio.round(2), (1 - 4 * res.times).round(2), res.info["refits"]
    (array([1.  , 0.96, 0.92]), array([1.  , 0.96, 0.92]), 4)
    """
    if not isinstance(surface, SphericalNeuralSurface):
        raise TypeError(f"surface must be a SphericalNeuralSurface (the flow refits its "
                        f"network), got {type(surface).__name__}; fit one with "
                        f"SphericalNeuralSurface.fit_shape")
    scheme = check_scheme(scheme)
    t_end, dt, T = check_times(t_end, dt, times, n_snapshots)
    check_choice(stability, "stability", STABILITY_MODES)
    o = MCFOptions.from_kwargs(**options)
    # o is checked; the conversions keep the types the flow has always used
    refit_steps, lr, growth, n_eval = int(o.refit_steps), float(o.lr), float(o.growth), \
        int(o.n_eval)
    if mesh_level is not None:
        mesh_level = _pos_int(mesh_level, "mesh_level", minimum=0)
    rng = as_generator(rng)
    t_start = time.perf_counter()

    area0 = _area(surface)
    # half the limit's count: the flow shrinks the area, and with it the limit
    N = default_points(area0 / 2, dt) if o.n_points is None else int(o.n_points)
    batch = N if o.batch is None else int(o.batch)
    limit0 = check_stability(dt, area0, N, stability, "mean_curvature_flow", scheme=scheme)
    S = surface
    surfaces, times, areas = [S], [0.0], [area0]
    meshes = [S.to_mesh(mesh_level)] if mesh_level is not None else None
    refit_rms, warned = [], stability == "ignore"
    total = sum(len(substeps(a, b, dt)) for a, b in zip(T[:-1], T[1:]))
    bar = Progress(total, "mcf", enabled=progress)
    steps, t, h = 0, 0.0, dt
    info = {"scheme": scheme, "n_points": N, "refit_steps": refit_steps, "lr": lr,
            "refits": 0, "refit_rms": refit_rms}

    def diverged(why):
        bar.close()
        msg = (f"mean curvature flow diverged at t = {t + h:.6g} (step {steps + 1}, scheme "
               f"{scheme!r}): {why}; the last good surface (t = {t:.6g}) is kept. Lower dt "
               f"(stability limit {limit0:.3g}) or lr ({lr:g})")
        if t > times[-1]:
            surfaces.append(S)
            times.append(t)
            areas.append(_area(S))
        err = DivergenceError(msg)
        err.result = MeanCurvatureFlowResult(
            np.array(times), surfaces, np.array(areas), meshes, limit0, steps,
            time.perf_counter() - t_start, msg, info)
        return err

    def quantities(surf, p):
        """``differential_quantities`` of a stage surface, or the divergence error."""
        try:
            dq = differential_quantities(surf, p)
        except DegenerateMapError as exc:
            raise diverged(f"the surface map became degenerate ({exc})") from None
        if not (np.all(np.isfinite(dq.x)) and np.all(np.isfinite(dq.H))):
            raise diverged("non-finite curvature or positions")
        return dq

    def refit(start, p, q, normals, stage_terms):
        """``start``'s network refitted to ``q`` at ``p`` (targets of the step from ``S``)."""
        target = _StepTarget(S, p, q, normals, [(u, c) for u, c in stage_terms if c != 0.0])
        net = start.net.copy()
        net.fit_readout(p, target.q, increment=True)
        if refit_steps:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", StabilityWarning)
                    S_new, _ = fit_sampler(
                        target, net=net, steps=refit_steps, batch=batch, lr=lr,
                        schedule="constant", warmup=0, normal_weight=o.normal_weight,
                        dtype=o.dtype, n_eval=n_eval, seed=rng, progress=False,
                        metadata=dict(S.metadata))
            except DivergenceError as exc:
                raise diverged(f"the refit diverged ({exc})") from None
            net = S_new.net
        if not np.all(np.isfinite(net.theta)):
            raise diverged("the refit produced non-finite parameters")
        net.fit_readout(p, target.q, increment=True)
        S_next = SphericalNeuralSurface(net, S.center, S.scale, metadata=dict(S.metadata))
        r = S_next.jet(p, 0) - q
        rms = float(np.sqrt(np.mean(np.einsum("ij,ij->i", r, r))))
        if not np.isfinite(rms):
            raise diverged("the refit produced non-finite positions")
        try:
            area_next = 4.0 * math.pi * float(area_element(S_next, p).mean())
        except DegenerateMapError as exc:
            raise diverged(f"the refitted map is degenerate ({exc})") from None
        if not area_next <= growth * area0:
            raise diverged(f"the area grew from {area0:.4g} to {area_next:.4g} (mean "
                           f"curvature flow decreases it)")
        refit_rms.append(rms)
        info["refits"] += 1
        return S_next, rms

    for a, b in zip(T[:-1], T[1:]):
        for h in substeps(a, b, dt):
            p = step_points(N, rng)
            dq = quantities(S, p)
            area_now = 4.0 * math.pi * float(dq.area_element.mean())
            if not warned and dt > stability_limit(area_now, N, scheme):
                warned = True
                check_stability(dt, area_now, N, "warn", "mean_curvature_flow",
                                during=f" at t = {t:.4g}, as the area shrank", scheme=scheme)
            v1 = -2.0 * dq.H[:, None] * dq.n
            if SCHEMES[scheme] is None:
                S_next, rms = refit(S, p, dq.x + h * v1, dq.n, [(S, h)])
            else:
                c_stage, c_last = SCHEMES[scheme]
                S_star, _ = refit(S, p, dq.x + c_stage * h * v1, dq.n, [(S, c_stage * h)])
                dq2 = quantities(S_star, p)
                v2 = -2.0 * dq2.H[:, None] * dq2.n
                S_next, rms = refit(S_star, p, dq.x + h * ((1 - c_last) * v1 + c_last * v2),
                                    dq2.n, [(S, (1 - c_last) * h), (S_star, c_last * h)])
            S = S_next
            steps += 1
            t += h
            bar.update(steps, t=f"{t:.4g}", area=f"{area_now:.4g}", fit=f"{rms:.1e}")
        S.metadata["mcf_time"] = float(b)
        surfaces.append(S)
        times.append(float(b))
        areas.append(_area(S))
        if meshes is not None:
            meshes.append(S.to_mesh(mesh_level))
    bar.close(steps)
    return MeanCurvatureFlowResult(np.array(times), surfaces, np.array(areas), meshes, limit0,
                                   steps, time.perf_counter() - t_start, "t_end", info)
