"""Heat flow ``f_t = Delta_S f`` of a scalar field on a surface map (paper Sec. 6).

Two schemes, both returning a :class:`HeatFlowResult` (``times`` ascending from 0 and the
matching ``fields``, each a field on the parameter sphere, ``h(S(p)) = g(p)``):

``method="network"`` (the paper's)
    The field is a small :class:`~sns_np.fields.NeuralField`. A refit evaluates a target such
    as ``f + dt Delta_S f`` at fixed sample points (``Delta_S`` by the divergence of the
    gradient, paper Eq. 13, with the surface's chart jets computed once) and refits the network
    from its previous weights: ``refit_steps`` Adam steps on the area-weighted squared error,
    then an exact least-squares solve of the read-out layer (in which the field is linear).
    ``scheme="euler"`` is the paper's step, one refit to ``f + dt L f`` (``L = Delta_S``);
    ``scheme="heun"`` (default) refits to ``f* = f + dt L f`` and then to
    ``f + dt/2 (L f + L f*)``; ``scheme="midpoint"`` to ``f* = f + dt/2 L f`` and then to
    ``f + dt L f*``. The two-stage schemes are second order, and for this linear equation
    identical (both multiply a mode of eigenvalue ``lambda`` by ``1 - z + z^2 / 2``,
    ``z = lambda dt``).
``method="spectral"``
    ``f(t) = sum_i exp(-lambda_i t) <f, phi_i> phi_i`` through the Laplace-Beltrami
    eigenmodes (:func:`sns_np.spectral.eigenmodes`, Rayleigh-Ritz by default) and the constant
    mode; exact in time (``dt`` is validated but not needed).

Every explicit scheme is stable for ``dt <= h^2 / (2 pi)`` with ``h = sqrt(A / N)`` the mean
spacing of the ``N`` sample points (docs/flows.md derives it); beyond it the flow warns or
refuses (``stability=``). A refit that produces non-finite values, or a field whose range grows
(the heat equation obeys a maximum principle), stops the flow with
:class:`~sns_np.errors.DivergenceError`; the partial result, whose last snapshot is the last
good field, is attached as ``exc.result``.

References
----------
T. Williamson and N. J. Mitra, "Neural Geometry Processing via Spherical Neural Surfaces",
Eurographics 2025, Sec. 6 (heat flow).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field

import numpy as np

from .._progress import Progress
from .._validation import as_generator, as_points, check_choice
from .._validation import check_positive_int as _pos_int
from ..errors import DivergenceError
from ..fields import NeuralField
from ..geometry import (
    laplace_beltrami_divgrad_from_jets,
    sphere_field_chart_jets,
    tangent_frame,
)
from ..geometry.chart import chart_jet_chunks
from ..nn.optim import Adam
from ..options import DEFAULT_SNAPSHOTS, HEAT_METHODS, HeatOptions
from ..protocol import field_jet
from ..sampling import fibonacci_sphere, surface_sample
from ._common import (
    DEFAULT_SCHEME,
    SCHEMES,
    STABILITY_MODES,
    check_scheme,
    check_stability,
    check_times,
    default_points,
    substeps,
)

__all__ = ["heat_flow", "HeatFlowResult", "HeatOptions", "ModalField", "HEAT_DEFAULTS"]

METHODS = HEAT_METHODS

#: the default options as a dict (kept for older code: :class:`HeatOptions` holds them)
HEAT_DEFAULTS = HeatOptions().to_dict()


@dataclass
class HeatFlowResult:
    """Snapshots of a heat flow.

    Attributes
    ----------
    times : (m,) float array, ascending, ``times[0] == 0``
    fields : list of m fields on the sphere (``jet(p, order)``); ``fields[j]`` is ``f(times[j])``
    method : {"network", "spectral"}
    stability_limit : float, ``h^2 / (2 pi)`` of the network scheme (NaN for "spectral")
    steps : int, explicit steps taken (0 for "spectral")
    seconds : float
    stopped : str, "t_end" or the divergence message
    info : dict, scheme details: for "network" the time ``scheme`` and the number of
        ``refits`` (one per step for Euler, two for the second-order schemes), sample size,
        initial fit error, ...; for "spectral" the projection residual, ...

    Examples
    --------
    >>> from sns_np.shapes import Sphere, SphericalHarmonic
    >>> res = heat_flow(Sphere(), SphericalHarmonic(1, 0), 0.5, 0.05, method="spectral", k=3,
    ...                 n_snapshots=2)
    >>> len(res), res.times.tolist(), res.method
    (3, [0.0, 0.25, 0.5], 'spectral')
    """

    times: np.ndarray
    fields: list
    method: str
    stability_limit: float = math.nan
    steps: int = 0
    seconds: float = 0.0
    stopped: str = "t_end"
    info: dict = field(default_factory=dict)

    def __len__(self):
        return len(self.times)

    def evaluate(self, p) -> np.ndarray:
        """All snapshots at sphere points ``p`` (n, 3), as an (n, m) array.

        Examples
        --------
        >>> from sns_np.shapes import Sphere, SphericalHarmonic
        >>> res = heat_flow(Sphere(), SphericalHarmonic(1, 0), 0.5, 0.05, method="spectral", k=3,
        ...                 n_snapshots=2)
        >>> f = res.evaluate(np.array([[0.0, 0.0, 1.0]]))            # Y_10 decays like exp(-2 t)
        >>> (f[0] / f[0, 0]).round(6), np.exp(-2 * res.times).round(6)
        (array([1.      , 0.606531, 0.367879]), array([1.      , 0.606531, 0.367879]))
        """
        p = as_points(p, "p")
        return np.stack([field_jet(f, p, 0) for f in self.fields], axis=1)

    def save(self, folder, surface, level: int = 5, overwrite: bool = False):
        """Write ``heat_000.ply`` ... (the surface mesh with the field ``f`` per vertex),
        ``heat_000.npz`` for neural fields, and ``flow.json`` (times, method, stop reason),
        into ``folder`` atomically. Returns the folder's Path.

        Examples
        --------
        >>> import os
        >>> from sns_np.shapes import Sphere, SphericalHarmonic
        >>> res = heat_flow(Sphere(), SphericalHarmonic(1, 0), 0.5, 0.05, method="spectral", k=3,
        ...                 n_snapshots=2)
        >>> folder = res.save("heat_out", Sphere(), level=1)
        >>> sorted(os.listdir(folder))
        ['flow.json', 'heat_000.ply', 'heat_001.ply', 'heat_002.ply']
        """
        from ..mesh import icosphere, write_mesh
        from ..protocol import surface_jet
        from ._common import atomic_folder
        P, F = icosphere(_pos_int(level, "level", minimum=0))
        V = surface_jet(surface, P, 0)
        vals = self.evaluate(P)

        def write(tmp):
            for j in range(len(self)):
                write_mesh(tmp / f"heat_{j:03d}.ply", V, F, {"f": vals[:, j]})
                if isinstance(self.fields[j], NeuralField):
                    self.fields[j].save(tmp / f"heat_{j:03d}.npz")
            (tmp / "flow.json").write_text(json.dumps(self.summary_dict(), indent=1))
        return atomic_folder(folder, write, overwrite)

    def summary_dict(self) -> dict:
        """The snapshot times, method, steps, timing, stop reason and scalar details as a JSON-ready
        dict (what ``flow.json`` holds).

        Examples
        --------
        >>> from sns_np.shapes import Sphere, SphericalHarmonic
        >>> res = heat_flow(Sphere(), SphericalHarmonic(1, 0), 0.5, 0.05, method="spectral", k=3,
        ...                 n_snapshots=2)
        >>> d = res.summary_dict()
        >>> d["flow"], d["method"], d["times"], d["stopped"]
        ('heat', 'spectral', [0.0, 0.25, 0.5], 't_end')
        """
        return {"flow": "heat", "method": self.method, "times": [float(t) for t in self.times],
                "steps": self.steps, "seconds": self.seconds, "stopped": self.stopped,
                "stability_limit": self.stability_limit,
                "info": {k: v for k, v in self.info.items() if _jsonable(v)}}


def _jsonable(v):
    return isinstance(v, (int, float, str, bool, type(None)))


class ModalField:
    """``g = c_0 phi_0 + sum_i c_i phi_i``: a combination of eigenfunctions, as a field.

    Parameters
    ----------
    constant : float, the value of ``c_0 phi_0`` (a constant)
    fields : list of k fields (``jet(p, order)``)
    coefficients : (k,) float array

    Examples
    --------
    >>> from sns_np.shapes import SphericalHarmonic
    >>> g = ModalField(1.0, [SphericalHarmonic(1, 0)], [2.0])
    >>> float(g(np.array([[0.0, 0.0, 1.0]]))[0]) == 1.0 + 2.0 * float(np.sqrt(3 / (4 * np.pi)))
    True
    """

    def __init__(self, constant, fields, coefficients):
        self.constant = float(constant)
        self.fields = list(fields)
        self.coefficients = np.asarray(coefficients, dtype=np.float64).ravel()
        if self.coefficients.shape != (len(self.fields),):
            raise ValueError(f"need one coefficient per field: {len(self.fields)} fields, "
                             f"{self.coefficients.shape[0]} coefficients")

    def jet(self, x, order: int = 0):
        """Value (n,), gradient (n, 3) and Hessian (n, 3, 3) of the combination at ``x`` (n, 3).

        Examples
        --------
        >>> from sns_np.shapes import SphericalHarmonic
        >>> g = ModalField(0.5, [SphericalHarmonic(1, 1)], [2.0])      # 0.5 + 2 Y_11
        >>> v, grad = g.jet(np.array([[1.0, 0.0, 0.0]]), 1)
        >>> c = np.sqrt(3 / (4 * np.pi))                              # Y_11 = c x
        >>> bool(np.isclose(v[0], 0.5 + 2 * c)), bool(np.allclose(grad, [[2 * c, 0.0, 0.0]]))
        (True, True)
        """
        x = as_points(x, "x")
        n = x.shape[0]
        out = [np.full(n, self.constant), np.zeros((n, 3)), np.zeros((n, 3, 3))][:order + 1]
        for f, c in zip(self.fields, self.coefficients):
            if c == 0.0:
                continue
            parts = field_jet(f, x, order)
            parts = (parts,) if order == 0 else parts
            for a, b in zip(out, parts):
                a += c * b
        return out[0] if order == 0 else tuple(out)

    def __call__(self, x):
        """The value at ``x`` (n, 3), (n,).

        Examples
        --------
        >>> from sns_np.shapes import SphericalHarmonic
        >>> g = ModalField(1.0, [SphericalHarmonic(1, 0), SphericalHarmonic(2, 0)], [0.0, 0.0])
        >>> g(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))           # only the constant
        array([1., 1.])
        """
        return self.jet(x, 0)

    value = __call__


# ------------------------------------------------------------------------------ public API

def heat_flow(surface, field, t_end, dt, method: str = HEAT_METHODS[0], *,
              scheme: str = DEFAULT_SCHEME, times=None, n_snapshots: int = DEFAULT_SNAPSHOTS,
              stability: str = "warn", rng=None, progress: bool = False,
              **options) -> HeatFlowResult:
    """Evolve a scalar field by the heat equation ``f_t = Delta_S f`` on a surface map.

    Parameters
    ----------
    surface : surface map (a SphericalNeuralSurface or any analytic shape); fixed
    field : field on the sphere (``jet(p, order)``): a NeuralField, SphericalHarmonic, ...
    t_end : float > 0
    dt : float > 0, the explicit time step ("network"; "spectral" is exact in time)
    method : {"network", "spectral"}
    scheme : {"heun", "midpoint", "euler"}, the time scheme of "network": "heun" (default) and
        "midpoint" are second order with two refits per step (identical for this linear
        equation), "euler" is the paper's first-order step with one refit; validated but
        unused by "spectral" (exact in time)
    times : sequence of floats in [0, t_end], optional, snapshot times (0 and ``t_end`` are
        always included); default ``n_snapshots + 1`` equally spaced times
    stability : {"warn", "raise", "ignore"}, what to do when ``dt`` exceeds the explicit
        limit ``h^2 / (2 pi)`` ("network" only; the same limit for every scheme)
    rng : None, int or Generator (seeds the network initialisation; ``None`` means 0)
    progress : bool, a progress line on stderr
    **options
        The fields of :class:`HeatOptions` (their defaults and help are there), checked
        before any work. "network": ``width``, ``depth`` (field network, as the paper's;
        ignored when ``field`` is already a NeuralField, which is copied), ``n_points``
        (fixed sample points; default at the stability limit), ``refit_steps`` (Adam steps
        per refit), ``lr``, ``init_steps`` (steps of the initial fit of a non-neural field),
        ``growth`` (divergence when ``max |f - mean|`` exceeds ``growth`` times its initial
        value). "spectral": ``k`` (non-constant modes), ``n_quad`` (quadrature nodes for the
        projection) and any option of :func:`sns_np.spectral.eigenmodes` via
        ``eigen_options`` (a dict).

    Returns
    -------
    HeatFlowResult

    Raises
    ------
    ValueError
        Bad options, or ``dt`` beyond the stability limit with ``stability="raise"``.
    DivergenceError
        A refit diverged; ``exc.result`` holds the snapshots up to the last good field.

    Examples
    --------
    >>> from sns_np.shapes import Sphere, SphericalHarmonic
    >>> res = heat_flow(Sphere(), SphericalHarmonic(2, 0), 0.1, 0.01, method="spectral", k=8)
    >>> p = np.array([[0.0, 0.0, 1.0]])
    >>> Y = SphericalHarmonic(2, 0).jet(p, 0)
    >>> bool(np.isclose(res.fields[-1](p)[0], np.exp(-0.6) * Y[0]))
    True
    """
    check_choice(method, "method", METHODS)
    scheme = check_scheme(scheme)
    t_end, dt, T = check_times(t_end, dt, times, n_snapshots)
    if not callable(getattr(field, "jet", None)):
        raise TypeError(f"field must follow the field protocol (jet(p, order)); got "
                        f"{type(field).__name__}")
    o = HeatOptions.from_kwargs(**options)
    if method == "spectral":
        return _spectral(surface, field, T, o)
    check_choice(stability, "stability", STABILITY_MODES)
    return _network(surface, field, T, dt, o, stability, as_generator(rng), progress, scheme)


# ------------------------------------------------------------------------------ spectral

def _spectral(surface, field, T, o):
    from ..spectral import HarmonicField, eigenmodes
    t0 = time.perf_counter()
    k = int(o.k)
    res = eigenmodes(surface, k, method="ritz", **dict(o.eigen_options or {}))
    quad = surface_sample(surface, int(o.n_quad), "quadrature")
    f = quad.values(field)
    Phi = res.evaluate(quad.p)
    c = Phi.T @ (quad.weights * f)
    mean = float(quad.weights @ f) / quad.area
    proj = mean + Phi @ c
    norm = math.sqrt(float(quad.weights @ (f * f)))
    resid = math.sqrt(float(quad.weights @ ((f - proj) ** 2))) / max(norm, 1e-300)
    if resid > 1e-2:
        import warnings
        warnings.warn(f"heat_flow(method='spectral'): the {k} modes represent the field only to "
                      f"a relative L2 residual of {resid:.2e}; raise k", RuntimeWarning,
                      stacklevel=3)
    fields = []
    harmonic = all(isinstance(phi, HarmonicField) for phi in res.eigenfunctions)
    for t in T:
        ct = c * np.exp(-res.eigenvalues * t)
        if harmonic:  # one expansion: exact and fast jets
            L = max(phi.L for phi in res.eigenfunctions)
            C = np.zeros((L + 1) ** 2)
            C[0] = mean * math.sqrt(4 * math.pi)  # Y_00 = 1 / sqrt(4 pi)
            for phi, a in zip(res.eigenfunctions, ct):
                C[:phi.coefficients.size] += a * phi.coefficients
            fields.append(HarmonicField(C, name=f"heat t={t:g}"))
        else:
            fields.append(ModalField(mean, res.eigenfunctions, ct))
    return HeatFlowResult(
        times=T, fields=fields, method="spectral", seconds=time.perf_counter() - t0,
        info={"k": k, "lambda_max": float(res.eigenvalues[-1]), "mean": mean,
              "projection_residual": resid, "eigen_converged": bool(res.converged)})


# ------------------------------------------------------------------------------ network

class _Sample:
    """Fixed sample points with the surface's chart jets (computed once) and area weights."""

    def __init__(self, surface, n, tol=1e-8):
        self.p = fibonacci_sphere(n)
        self.R = tangent_frame(self.p)
        self.JR = np.empty((n, 3, 2))
        self.S2 = np.empty((n, 3, 2, 2))
        for sl, (_, JR, _, S2), _ in chart_jet_chunks(surface, self.p, 2, R=self.R, chunk=16384,
                                                      tol=tol):
            self.JR[sl], self.S2[sl] = JR, S2
        d = np.linalg.norm(np.cross(self.JR[:, :, 0], self.JR[:, :, 1]), axis=1)
        self.w = 4 * math.pi * d / n  # equal-area lattice: integral ~= sum w_i g_i
        self.area = float(self.w.sum())

    def laplacian(self, f):
        v, g, Hs = field_jet(f, self.p, 2)
        f_a, f_ab = sphere_field_chart_jets(g, Hs, self.R, self.p)
        return v, laplace_beltrami_divgrad_from_jets(f_a, f_ab, self.JR, self.S2)


def _refit(f, sample, target, steps, opt):
    """Adam steps on ``sum w (g - target)^2 / sum w``, then the exact weighted read-out."""
    net, p, w = f.net, sample.p, sample.w / sample.w.sum()
    c = f.scale / net.out_dim
    loss = math.nan
    for _ in range(steps):
        def loss_fn(y, JD, sl):
            r = c * y.sum(axis=1) - target[sl]
            dy = np.repeat((2.0 * c * w[sl] * r)[:, None], net.out_dim, axis=1)
            return float(w[sl] @ (r * r)), dy, None
        loss, grad = net.value_and_grad(p, loss_fn, order=0)
        if not (np.isfinite(loss) and np.all(np.isfinite(grad))):
            return math.inf
        opt.step(net.theta, grad)
    d = net.fit_readout(p, target, weights=w, increment=True, scale=f.scale, current=f(p))
    if not np.all(np.isfinite(d)):
        return math.inf
    r = target - f(p)
    return float(w @ (r * r))


def _network(surface, field, T, dt, o, stability, rng, progress, scheme):
    t_start = time.perf_counter()
    # o (HeatOptions) is checked; the conversions keep the types the scheme has always used
    refit_steps, init_steps = int(o.refit_steps), int(o.init_steps)
    lr, growth = float(o.lr), float(o.growth)
    area0 = surface_sample(surface, 4096, "quadrature").area
    n = default_points(area0, dt) if o.n_points is None else int(o.n_points)
    limit = check_stability(dt, area0, n, stability, "heat_flow(method='network')",
                            scheme=scheme)
    sample = _Sample(surface, n)

    if isinstance(field, NeuralField):
        f = field.copy()
        init_rms = 0.0
    else:
        f = NeuralField(int(o.width), int(o.depth), seed=rng)
        target0 = field_jet(field, sample.p, 0)
        opt0 = Adam(1e-2)
        ms = _refit(f, sample, target0, init_steps, opt0)
        init_rms = math.sqrt(ms) / max(math.sqrt(float(sample.w @ target0 ** 2) / sample.area),
                                       1e-300)
    opt = Adam(lr)
    v0 = f(sample.p)
    mean0 = float(sample.w @ v0) / sample.area
    range0 = float(np.abs(v0 - mean0).max())
    fields, times = [f.copy()], [0.0]
    steps, t, stopped = 0, 0.0, "t_end"
    total = sum(len(substeps(a, b, dt)) for a, b in zip(T[:-1], T[1:]))
    bar = Progress(total, "heat", enabled=progress)
    info = {"scheme": scheme, "n_points": n, "area": sample.area,
            "initial_fit_rel_rms": init_rms, "refit_steps": refit_steps, "refits": 0,
            "width": f.net.width, "depth": f.net.depth}
    last_ms = 0.0
    coeffs = SCHEMES[scheme]

    def refit(target):
        """Refit ``f`` to ``target``; a DivergenceError if it fails or the range grows."""
        ms = _refit(f, sample, target, refit_steps, opt)
        vals = f(sample.p)
        bad = not (np.isfinite(ms) and np.all(np.isfinite(vals)))
        spread = math.inf if bad else float(np.abs(vals - mean0).max())
        if bad or spread > growth * range0 + 1e-12:
            why = ("the refit produced non-finite values" if bad else
                   f"max |f - mean| grew from {range0:.3g} to {spread:.3g} (the heat "
                   f"equation never increases it)")
            raise DivergenceError(
                f"heat flow diverged at t = {t + h:.6g} (step {steps + 1}, scheme {scheme!r}): "
                f"{why}; the last good field (t = {t:.6g}) is kept. Lower dt (stability limit "
                f"{limit:.3g}) or lr ({lr:g})")
        info["refits"] += 1
        return ms

    h = dt
    try:
        for a, b in zip(T[:-1], T[1:]):
            for h in substeps(a, b, dt):
                good = f.theta.copy()
                try:
                    v, lap = sample.laplacian(f)
                    if coeffs is None:                     # f+ = f + h L f
                        last_ms = refit(v + h * lap)
                    else:                                  # f* = f + a h L f, then
                        c_stage, c_last = coeffs           # f+ = f + h ((1-b) L f + b L f*)
                        refit(v + c_stage * h * lap)
                        _, lap2 = sample.laplacian(f)
                        last_ms = refit(v + h * ((1 - c_last) * lap + c_last * lap2))
                except DivergenceError:
                    f.theta[...] = good
                    raise
                steps += 1
                t += h
                bar.update(steps, t=f"{t:.4g}", fit=f"{math.sqrt(last_ms):.1e}")
            fields.append(f.copy())
            times.append(float(b))
    except DivergenceError as exc:
        bar.close()
        if t > times[-1]:
            fields.append(f.copy())
            times.append(t)
        exc.result = HeatFlowResult(np.array(times), fields, "network", limit, steps,
                                    time.perf_counter() - t_start, str(exc), info)
        raise
    bar.close(steps)
    info["last_refit_rms"] = math.sqrt(last_ms)
    return HeatFlowResult(np.array(times), fields, "network", limit, steps,
                          time.perf_counter() - t_start, stopped, info)
