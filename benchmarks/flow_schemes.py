"""Time schemes of the flows (issue 15): accuracy, measured order and cost per unit of accuracy.

Run (one thread, as the figures in docs/flows.md)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/flow_schemes.py                     # everything, about 10 minutes
    python benchmarks/flow_schemes.py --parts sphere cost     # a subset

Parts, each printed as a table:

``sphere``
    Mean curvature flow of a fitted unit sphere to ``r = 0.5`` (``t = 3/16``) in 20 steps with
    the default refit options, per scheme: the error of the radius law ``r = sqrt(1 - 4 t)``
    at every step (``r = sqrt(A / 4 pi)``), refits and seconds.
``order``
    The same flow with 5, 10, 20, 40 steps: the signed radius error at ``r = 0.5``, the error
    against a reference run (Heun, 80 steps; this removes the fitted sphere's own small,
    step-independent deviation from the law) and its ratio when the step halves (4: second
    order, 2: first order), with the default refits and with read-out refits only
    (``refit_steps=0``).
``ellipsoid``
    A fitted ellipsoid (1, 1.3, 0.7) flowed to ``t = 0.1`` with 4, 8, 16, 32 steps against a
    reference run (Heun, 128 steps): RMS position error over 2,000 sphere points relative to the
    diameter, area error, and their ratios; read-out refits (``refit_steps=0``, 512 points)
    and, with a coarser grid, the default Adam refits.
``cost``
    The fewest steps, refits and seconds with which each scheme keeps the sphere's radius law
    within 1% at every step down to ``r = 0.5``, with the default options (the start inside
    the stability limit) and without that constraint.
``heat``
    Heat flow of ``Y_l1`` on the unit sphere to the time of half amplitude
    ``t = ln 2 / l(l+1)`` with 10 and 40 steps, per scheme: the amplitude error against
    ``exp(-l(l+1) t)``, split into the scheme's time error ``R(z)^n / exp(-lambda t) - 1``
    (closed form, :func:`sns_np.flows.amplification`) and the refits' error (the amplitude
    against ``R(z)^n``); and the network's own limit, the relative L2 error of the final field
    against ``exp(-lambda t) Y`` (and of the initial fit).

Nothing is asserted (the tests assert the thresholds of issue 15). Seconds on a shared machine
are noisy: compare them within one run; the load average is printed first.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from sns_np.flows import (  # noqa: E402
    StabilityWarning,
    amplification,
    heat_flow,
    mean_curvature_flow,
)
from sns_np.sampling import surface_sample  # noqa: E402
from sns_np.shapes import Ellipsoid, Sphere, SphericalHarmonic  # noqa: E402
from sns_np.surface import SphericalNeuralSurface  # noqa: E402

SCHEMES = ("euler", "heun", "midpoint")
T_SPHERE = 3 / 16  # r = 0.5
FIT = dict(width=32, depth=2, steps=300, batch=1024, progress=False, n_eval=512, lr=1e-3,
           normal_weight=1e-4, input_scale=2.0, dtype="float64")


def fitted(shape, seed):
    S, rep = SphericalNeuralSurface.fit_shape(shape, seed=seed, **FIT)
    return S, rep


def radius_errors(res):
    """|r / sqrt(1 - 4 t) - 1| per snapshot, r = sqrt(A / 4 pi)."""
    return np.abs(np.sqrt(res.areas / (4 * np.pi)) / np.sqrt(1 - 4 * res.times) - 1)


def sphere_flow(S, scheme, n, snapshots=None, stability="ignore", **options):
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StabilityWarning)
        res = mean_curvature_flow(S, T_SPHERE, T_SPHERE / n, scheme=scheme, rng=0,
                                  n_snapshots=snapshots or n, stability=stability, **options)
    return res, time.perf_counter() - t0


def part_sphere(S):
    print("\n== MCF, fitted unit sphere to r = 0.5 in 20 steps (default refits): radius error "
          "|r / sqrt(1 - 4t) - 1| at t = 3/80, 3/40, ..., 3/16 (every 4th step), max over all "
          "20 steps")
    for scheme in SCHEMES:
        res, sec = sphere_flow(S, scheme, 20)
        e = radius_errors(res)
        print(f"{scheme:9s} refits {res.info['refits']:3d}  N {res.info['n_points']:4d}  "
              + " ".join(f"{x:.2e}" for x in e[4::4])
              + f"  max {e.max():.2e}  (r^2 error at r = 0.5: "
              f"{abs(res.areas[-1] / (4 * np.pi) / 0.25 - 1):.2e})  {sec:5.1f} s")


def part_order(S, n_ref=80):
    for label, opts in (("default refits (100 Adam steps)", {}),
                        ("read-out refits only (refit_steps=0)", {"refit_steps": 0})):
        ref, sec = sphere_flow(S, "heun", n_ref, snapshots=1, **opts)
        r_ref = math.sqrt(ref.areas[-1] / (4 * np.pi))
        print(f"\n== MCF order on the sphere, {label}: at r = 0.5, the signed radius error "
              f"r / 0.5 - 1 and the error against a reference run (Heun, {n_ref} steps, "
              f"r_ref / 0.5 - 1 = {r_ref / 0.5 - 1:+.2e}, {sec:.0f} s), and its ratio when "
              f"the step halves")
        for scheme in SCHEMES:
            errs, cells = [], []
            for n in (5, 10, 20, 40):
                res, _ = sphere_flow(S, scheme, n, snapshots=1, **opts)
                r = math.sqrt(res.areas[-1] / (4 * np.pi))
                errs.append(abs(r / r_ref - 1))
                cells.append(f"n={n:2d} {r / 0.5 - 1:+.2e} {errs[-1]:.2e}")
            ratios = " ".join(f"{a / b:5.2f}" for a, b in zip(errs[:-1], errs[1:]))
            print(f"{scheme:9s} " + "  ".join(cells) + f"   ratios {ratios}")


def part_ellipsoid():
    E, rep = fitted(Ellipsoid(1.0, 1.3, 0.7), 1)
    p = surface_sample(Sphere(), 2000, "quadrature").p
    for label, opts, ns, nref in (
            ("read-out refits (refit_steps=0), N = 512", {"refit_steps": 0}, (4, 8, 16, 32),
             128),
            ("default Adam refits (100 steps), N = 512", {}, (4, 8, 16), 64)):
        def run(scheme, n):
            t0 = time.perf_counter()
            res = mean_curvature_flow(E, 0.1, 0.1 / n, scheme=scheme, n_snapshots=1, rng=0,
                                      n_points=512, stability="ignore", **opts)
            return res, time.perf_counter() - t0
        ref, sec = run("heun", nref)
        X = ref.surfaces[-1](p)
        diam = float(np.linalg.norm(X.max(axis=0) - X.min(axis=0)))
        print(f"\n== MCF order on the ellipsoid (1, 1.3, 0.7) to t = 0.1, {label}; reference "
              f"Heun {nref} steps ({sec:.1f} s, area {ref.areas[-1]:.5f} from "
              f"{ref.areas[0]:.5f}): RMS position error / diameter, area error, ratios")
        for scheme in SCHEMES:
            pos, area, cells = [], [], []
            for n in ns:
                res, sec = run(scheme, n)
                pos.append(np.sqrt(np.mean(np.sum((res.surfaces[-1](p) - X) ** 2, axis=1)))
                           / diam)
                area.append(res.areas[-1] / ref.areas[-1] - 1)
                cells.append(f"n={n:2d} {pos[-1]:.2e} {area[-1]:+.1e}")
            rp = " ".join(f"{a / b:5.2f}" for a, b in zip(pos[:-1], pos[1:]))
            ra = " ".join(f"{a / b:5.2f}" for a, b in zip(area[:-1], area[1:]))
            print(f"{scheme:9s} " + "  ".join(cells) + f"   ratios pos {rp} | area {ra}")


def fewest_steps(S, scheme, stability, tol=0.01, n_max=256):
    """Fewest steps keeping every step's radius error below ``tol`` (errors shrink with n)."""
    runs = {}

    def ok(n):
        if n not in runs:
            try:
                res, sec = sphere_flow(S, scheme, n, stability=stability)
            except ValueError:           # beyond the stability limit at the start
                runs[n] = (False, None, None)
                return False
            runs[n] = (bool(radius_errors(res).max() < tol), res, sec)
        return runs[n][0]
    lo, hi = 0, 1
    while not ok(hi):
        lo, hi = hi, 2 * hi
        if hi > n_max:
            return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return hi, runs[hi][1], runs[hi][2], len(runs)


def part_cost(S):
    print("\n== Cost of 1% on the sphere: fewest steps with the radius law within 1% at every "
          "step down to r = 0.5 (default refit options; seconds of that run)")
    for stability, label in (("raise", "start within the stability limit"),
                             ("ignore", "stability limit ignored")):
        print(f"-- {label}")
        for scheme in SCHEMES:
            found = fewest_steps(S, scheme, stability)
            if found is None:
                print(f"{scheme:9s} not reached in 256 steps")
                continue
            n, res, sec, tried = found
            print(f"{scheme:9s} steps {n:3d}  refits {res.info['refits']:3d}  N "
                  f"{res.info['n_points']:4d}  max error {radius_errors(res).max():.2e}  "
                  f"{sec:5.1f} s  ({tried} runs searched)")


def part_heat():
    quad = surface_sample(Sphere(), 20000, "quadrature")
    print("\n== Heat flow of Y_l1 on the unit sphere to t = ln 2 / l(l+1) (default options: N at "
          "the stability limit, 100 Adam steps per refit): amplitude error = time error "
          "(closed form) + refit error; field = relative L2 error of the final field against "
          "exp(-lambda t) Y (init: of the initial fit)")
    for l in (1, 2, 3):
        Y = SphericalHarmonic(l, 1)
        lam = l * (l + 1)
        t_half = math.log(2) / lam
        y = quad.values(Y)
        ny = math.sqrt(float(quad.weights @ (y * y)))
        for n in (10, 40):
            for scheme in SCHEMES:
                dt = t_half / n
                t0 = time.perf_counter()
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always", StabilityWarning)
                    res = heat_flow(Sphere(), Y, t_half, dt, scheme=scheme, n_snapshots=1,
                                    rng=1)
                sec = time.perf_counter() - t0
                beyond = " (dt beyond the limit of N = 64, the smallest default)" if caught else ""
                vals = [quad.values(f) for f in res.fields]
                a = float(quad.weights @ (vals[-1] * y)) / float(quad.weights @ (vals[0] * y))
                prod = float(amplification(-lam * dt, scheme)) ** n
                field = math.sqrt(float(quad.weights @ (vals[-1] - 0.5 * y) ** 2)) / (0.5 * ny)
                print(f"l={l} n={n:2d} {scheme:9s} N {res.info['n_points']:5d} refits "
                      f"{res.info['refits']:3d}  amplitude {a / 0.5 - 1:+.2e} = time "
                      f"{prod / 0.5 - 1:+.2e} + refits {a / prod - 1:+.2e}   field "
                      f"{field:.2e} (init {res.info['initial_fit_rel_rms']:.2e})  {sec:5.1f} s"
                      f"{beyond}",
                      flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--parts", nargs="+", default=["sphere", "order", "ellipsoid", "cost",
                                                   "heat"],
                    choices=["sphere", "order", "ellipsoid", "cost", "heat"])
    args = ap.parse_args(argv)
    threads = {k: os.environ.get(k, "unset") for k in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS",
                                                        "OPENBLAS_NUM_THREADS")}
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}; threads {threads}")
    t0 = time.perf_counter()
    S = None
    if {"sphere", "order", "cost"} & set(args.parts):
        S, rep = fitted(Sphere(), 0)
        print(f"fitted unit sphere: width 32, depth 2, 300 steps, held-out position RMS "
              f"{rep.position_rms:.1e}, r(0) - 1 = "
              f"{math.sqrt(surface_sample(S, 4096, 'quadrature').area / (4 * np.pi)) - 1:+.1e}")
        sphere_flow(S, "euler", 2, snapshots=1)  # warm-up: the first call compiles kernels
    for part in args.parts:
        {"sphere": lambda: part_sphere(S), "order": lambda: part_order(S),
         "ellipsoid": part_ellipsoid, "cost": lambda: part_cost(S), "heat": part_heat}[part]()
        sys.stdout.flush()
    print(f"\ntotal {time.perf_counter() - t0:.0f} s; load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
