"""Fitting a SphericalNeuralSurface to the zero set of a signed distance function (paper Sec. 6).

The paper's procedure (its DeepSDF camera): start from a surface, then repeatedly

1. sample the current surface, ``x_i = S(p_i)``;
2. move the samples onto the zero set along the gradient, ``x <- x - f(x) grad f / |grad f|^2``
   (one step is exact for a true SDF; ``newton`` steps converge for any smooth implicit
   function with a non-vanishing gradient near the surface);
3. refit the network to the pairs ``(p_i, x_i)`` (with the SDF's normals
   ``grad f / |grad f|``), from its current weights.

Starting surfaces (``init=``): ``"radial"`` (default) traces rays from ``center`` to the zero
set, so the first fit already sees surface points (for shapes star-shaped about ``center``);
a SphericalNeuralSurface (fine-tuned); a mesh ``(V, F)`` (fitted first, as the paper does with
a marching-cubes mesh); or any analytic surface map.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .._validation import as_generator, as_points, check_positive_float
from .._validation import check_positive_int as _pos_int
from ..errors import ShapeError
from ..sampling import uniform_sphere
from .fit import fit_sampler
from .model import SphericalNeuralSurface

__all__ = ["fit_sdf", "SDFFitReport", "project_to_zero_set"]


@dataclass
class SDFFitReport:
    """What :func:`fit_sdf` did and how close the result is to the zero set.

    Distances are ``|f(S(p))| / |grad f(S(p))|`` (the distance for a true SDF, its first-order
    estimate otherwise) at ``n_eval`` held-out sphere points, in the SDF's units, and relative
    to the bounding-box diagonal of the result.

    Examples
    --------
    >>> rep = SDFFitReport(iterations=2, seconds=1.5, init="radial", distance_mean=0.01,
    ...                    distance_max=0.05, bbox_diagonal=4.0)
    >>> rep.relative_mean, rep.relative_max
    (0.0025, 0.0125)
    """

    iterations: int = 0
    seconds: float = 0.0
    init: str = ""
    distance_mean: float = math.nan
    distance_max: float = math.nan
    bbox_diagonal: float = math.nan
    history: list = field(default_factory=list)

    @property
    def relative_mean(self) -> float:
        return self.distance_mean / self.bbox_diagonal

    @property
    def relative_max(self) -> float:
        return self.distance_max / self.bbox_diagonal

    def summary(self) -> str:
        """The report in one line.

        Examples
        --------
        >>> rep = SDFFitReport(iterations=2, seconds=1.5, init="radial", distance_mean=0.01,
        ...                    distance_max=0.05, bbox_diagonal=4.0)
        >>> print(rep.summary())
        fit_sdf (radial start, 2 projection iterations, 1.5 s): distance to the zero set mean
        0.01 (2.50e-03 of the bbox diagonal), max 0.05 (1.25e-02)
        """
        return (f"fit_sdf ({self.init} start, {self.iterations} projection iterations, "
                f"{self.seconds:.1f} s): distance to the zero set mean {self.distance_mean:.3g}"
                f" ({self.relative_mean:.2e} of the bbox diagonal), max {self.distance_max:.3g}"
                f" ({self.relative_max:.2e})")


class _SDF:
    """A validated SDF with its gradient (given, or central differences of step ``eps``)."""

    def __init__(self, sdf, grad, eps):
        if not callable(sdf):
            raise TypeError(f"sdf must be a callable sdf(x) -> (n,), got {type(sdf).__name__}")
        if grad is not None and not callable(grad):
            raise TypeError(f"grad must be None or a callable grad(x) -> (n, 3), got "
                            f"{type(grad).__name__}")
        self.f, self.g, self.eps = sdf, grad, eps

    def __call__(self, x):
        v = np.asarray(self.f(x), dtype=np.float64).reshape(-1)
        if v.shape != (x.shape[0],):
            raise ShapeError(f"sdf(x) must return one value per point, shape ({x.shape[0]},); "
                             f"got {np.shape(self.f(x))}")
        return v

    def grad(self, x):
        if self.g is not None:
            G = np.asarray(self.g(x), dtype=np.float64)
            if G.shape != x.shape:
                raise ShapeError(f"grad(x) must return shape {x.shape}, got {G.shape}")
            return G
        G = np.empty_like(x)
        for i in range(3):
            e = np.zeros(3)
            e[i] = self.eps
            G[:, i] = (self(x + e) - self(x - e)) / (2.0 * self.eps)
        return G


def project_to_zero_set(sdf, x, grad=None, newton: int = 3, eps: float = 1e-6):
    """Move points onto the zero set: ``x <- x - f(x) grad f / |grad f|^2``, ``newton`` times.

    Parameters
    ----------
    sdf : callable ``sdf(x) -> (n,)``
    x : (n, 3) float array
    grad : callable ``grad(x) -> (n, 3)``, optional (central differences of step ``eps``)

    Returns
    -------
    y : (n, 3) float array, projected points
    normals : (n, 3) float array, ``grad f / |grad f|`` at ``y``

    Examples
    --------
    >>> f = lambda x: np.linalg.norm(x, axis=1) - 2.0
    >>> y, nrm = project_to_zero_set(f, np.array([[3.0, 0.0, 0.0]]))
    >>> y.round(8), nrm.round(6)
    (array([[2., 0., 0.]]), array([[1., 0., 0.]]))
    """
    F = sdf if isinstance(sdf, _SDF) else _SDF(sdf, grad, eps)
    y = as_points(x, "x").copy()
    for _ in range(_pos_int(newton, "newton")):
        g = F.grad(y)
        g2 = np.einsum("ij,ij->i", g, g)
        if not np.all(g2 > 0):
            k = int(np.argmax(~(g2 > 0)))
            raise ValueError(f"the SDF gradient vanishes at {y[k]}; cannot project onto the "
                             f"zero set there")
        y = y - (F(y) / g2)[:, None] * g
    g = F.grad(y)
    return y, g / np.linalg.norm(g, axis=1, keepdims=True)


def _trace_rays(F, center, p, r_max, tol):
    """``r(p)`` with ``f(center + r p) = 0``, the first crossing: march, then bisect."""
    n = p.shape[0]
    lo = np.zeros(n)
    hi = np.full(n, np.nan)
    t = np.zeros(n)
    active = np.ones(n, bool)
    for _ in range(400):
        if not active.any():
            break
        x = center + t[active, None] * p[active]
        v = F(x)
        crossed = v >= 0
        idx = np.flatnonzero(active)
        hi[idx[crossed]] = t[idx[crossed]]
        active[idx[crossed]] = False
        go = idx[~crossed]
        lo[go] = t[go]
        t[go] += np.maximum(0.5 * np.abs(v[~crossed]), 1e-3 * r_max)
        over = go[t[go] > r_max]
        if over.size:
            raise ValueError(f"the ray from center {center} in direction {p[over[0]]} does not "
                             f"reach the zero set within radius {r_max:g}; pass a center "
                             f"inside the shape, a larger radius_max, or another init")
    if active.any():
        raise ValueError("ray marching did not reach the zero set in 400 steps")
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        v = F(center + mid[:, None] * p)
        pos = v >= 0
        hi = np.where(pos, mid, hi)
        lo = np.where(pos, lo, mid)
        if np.max(hi - lo) < tol:
            break
    return 0.5 * (lo + hi)


class _PoolTarget:
    """A fixed pool of (sphere point, surface point, normal) in a normalised frame."""

    def __init__(self, p, x, normals, center, scale, name):
        self.p, self.normals = p, normals
        self.center, self.scale = center, scale
        self.q = (x - center) / scale
        self.bbox_diagonal = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
        self.fingerprint = name
        self._eval = None

    def sample(self, n, rng):
        N = self.p.shape[0]
        idx = rng.permutation(N) if n >= N else rng.choice(N, n, replace=False)
        return self.p[idx], self.q[idx], self.normals[idx]

    def evaluate_at(self, p):
        x, nrm = self._eval(p)
        return (x - self.center) / self.scale, nrm


def fit_sdf(sdf, grad=None, *, init="radial", center=(0.0, 0.0, 0.0), radius_max=100.0,
            iterations: int = 3, steps: int | None = None, init_steps: int | None = None,
            n_pool: int = 16384, newton: int = 3, eps: float | None = None, tol: float = 0.0,
            n_eval: int = 4096, seed=0, progress: bool = True, **fit_options):
    """Fit a SphericalNeuralSurface to the zero set of ``sdf``.

    Parameters
    ----------
    sdf : callable ``sdf(x)``, x (n, 3) -> (n,), negative inside
    grad : callable ``grad(x)`` -> (n, 3), optional; central differences when omitted
    init : "radial", SphericalNeuralSurface, (V, F) mesh or surface map
        The starting surface (see the module notes).
    center : (3,) point inside the shape, the origin of the rays ("radial")
    radius_max : float, how far rays are traced before giving up ("radial")
    iterations : int >= 0, project-and-refit rounds after the start
    steps : int, fitting steps per round (default: the fitting default); ``init_steps`` for the
        starting fit (default the same)
    n_pool : int, surface samples projected per round (batches are drawn from them)
    newton : int, projection steps per round
    eps : float, central-difference step of the gradient (default 1e-6 times the size)
    tol : float, stop early when the held-out mean distance, relative to the bbox diagonal,
        is below ``tol``
    n_eval : int, held-out sphere points of the report
    seed : int or Generator
    progress : bool
    **fit_options
        Passed to :func:`sns_np.surface.fit_sampler` (``width``, ``depth``, ``batch``, ``lr``,
        ``normal_weight``, ``dtype``, ...).

    Returns
    -------
    (SphericalNeuralSurface, SDFFitReport)

    Examples
    --------
    A sphere of radius 2, from its SDF (a tiny network and budget; the default network is
    the paper's 256 x 8):

    >>> sdf = lambda x: np.linalg.norm(x, axis=1) - 2.0
    >>> S, report = fit_sdf(sdf, width=16, depth=1, steps=60, iterations=1, n_eval=512,
    ...                     progress=False)
    >>> r = np.linalg.norm(S(np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]])), axis=1)
    >>> bool(np.allclose(r, 2.0, atol=0.1)), bool(report.relative_mean < 0.02)
    (True, True)
    """
    t0 = time.perf_counter()
    rng = as_generator(seed)
    center = np.asarray(center, dtype=np.float64)
    if center.shape != (3,) or not np.all(np.isfinite(center)):
        raise ValueError(f"center must be 3 finite numbers, got {center!r}")
    iterations = _pos_int(iterations, "iterations", minimum=0)
    n_pool = _pos_int(n_pool, "n_pool", minimum=16)
    n_eval = _pos_int(n_eval, "n_eval")
    radius_max = check_positive_float(radius_max, "radius_max")
    tol = check_positive_float(tol, "tol", allow_zero=True)
    for bad in ("net", "seed", "progress", "metadata", "steps"):
        fit_options.pop(bad, None)
    F = _SDF(sdf, grad, 1.0)
    fit_options.setdefault("n_eval", 1024)  # the report below measures on its own points
    # the options the SDF fits were measured with (docs/flows.md), not the mesh-fitting
    # defaults, which adapt the first layer and the rate to detailed meshes
    common = dict(seed=rng, progress=progress, **{"lr": 1e-4, "input_scale": 4.0,
                                                  "warmup": 50, **fit_options})

    # ------------------------------------------------------------------ the start
    if isinstance(init, str):
        if init != "radial":
            raise ValueError(f"unknown init {init!r}; expected 'radial', a "
                             f"SphericalNeuralSurface, a (V, F) mesh or a surface map")
        c0 = F(center[None])[0]
        if not c0 < 0:
            raise ValueError(f"sdf(center) = {c0:.4g} >= 0: the center {center.tolist()} is "
                             f"not inside the shape; pass center= a point inside")
        probe = _trace_rays(F, center, uniform_sphere(256, rng), radius_max, 1e-6)
        size = float(probe.max())
        F.eps = eps if eps is not None else 1e-6 * size

        def radial(p):
            r = _trace_rays(F, center, p, radius_max, 1e-12 * size)
            x = center + r[:, None] * p
            g = F.grad(x)
            return x, g / np.linalg.norm(g, axis=1, keepdims=True)

        p = uniform_sphere(n_pool, rng)
        x, nrm = radial(p)
        area_scale = math.sqrt(np.mean(np.linalg.norm(x - center, axis=1) ** 2))
        target = _PoolTarget(p, x, nrm, x.mean(axis=0), area_scale, "sdf-radial")
        target._eval = radial
        S, _ = fit_sampler(target, steps=init_steps or steps, metadata={"source": "sdf"},
                           **common)
        init_name = "radial"
    else:
        if isinstance(init, SphericalNeuralSurface):
            S = init
        elif isinstance(init, tuple) and len(init) == 2:
            S, _ = SphericalNeuralSurface.fit(init[0], init[1], steps=init_steps or steps,
                                              **common)
        elif callable(getattr(init, "jet", None)):
            S, _ = SphericalNeuralSurface.fit_shape(init, steps=init_steps or steps, **common)
        else:
            raise TypeError(f"init must be 'radial', a SphericalNeuralSurface, a (V, F) mesh "
                            f"or a surface map; got {type(init).__name__}")
        init_name = type(init).__name__ if not isinstance(init, tuple) else "mesh"
        y = S.jet(uniform_sphere(1024, rng), 0)
        size = float(np.linalg.norm(y.max(axis=0) - y.min(axis=0)))
        F.eps = eps if eps is not None else 1e-6 * size

    # ------------------------------------------------------------------ project and refit
    p_eval = uniform_sphere(n_eval, np.random.default_rng(2**31 - 1))
    report = SDFFitReport(init=init_name)

    def measure(S):
        x = S.jet(p_eval, 0)
        g = F.grad(x)
        d = np.abs(F(x)) / np.linalg.norm(g, axis=1)
        diag = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
        return float(d.mean()), float(d.max()), diag

    dmean, dmax, diag = measure(S)
    report.history.append({"iteration": 0, "distance_mean": dmean, "distance_max": dmax})
    it = 0
    while it < iterations and not (tol and dmean / diag < tol):
        it += 1
        p = uniform_sphere(n_pool, rng)
        x, nrm = project_to_zero_set(F, S.jet(p, 0), newton=newton)
        target = _PoolTarget(p, x, nrm, S.center, S.scale, f"sdf-iteration-{it}")
        S_prev = S

        def projected(q, S_prev=S_prev):
            return project_to_zero_set(F, S_prev.jet(q, 0), newton=newton)

        target._eval = projected
        net = S.net.copy()
        net.fit_readout(p, target.q, increment=True)
        S, _ = fit_sampler(target, net=net, steps=steps, metadata=dict(S.metadata), **common)
        S.net.fit_readout(p, target.q, increment=True)
        dmean, dmax, diag = measure(S)
        report.history.append({"iteration": it, "distance_mean": dmean, "distance_max": dmax})
    report.iterations = it
    report.distance_mean, report.distance_max, report.bbox_diagonal = dmean, dmax, diag
    report.seconds = time.perf_counter() - t0
    S.metadata.update(source="sdf", sdf_fit={"init": init_name, "iterations": it,
                                             "distance_mean": dmean, "distance_max": dmax,
                                             "bbox_diagonal": diag})
    return S, report
