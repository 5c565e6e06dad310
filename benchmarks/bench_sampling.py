"""The cost of a fitting step drawn by the error against one drawn by area.

Error-weighted sampling (``FitOptions.sampling="error"``, docs/fitting.md) adds a few small
array operations per step (the draw of a cell, the running sums, every 10 steps new
probabilities); this benchmark checks that they cost nothing next to the network. It fits
spot_triangulated with the detailed defaults for ``--steps`` steps in each mode, alternately,
``--repeats`` times, from one embedding, and prints the milliseconds per step of each (from
the fit history, after its first record) and their ratio (1.0: no cost).

Measured on the project's machine (2026-12-01, a slow day): 82.4 and 77.8 ms by area, 76.0
and 77.0 ms by error: a ratio of 0.96.

Run::

    python benchmarks/bench_sampling.py [--steps 500] [--repeats 2]

Nothing is asserted; measure on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from sns_np.mesh import load, spherical_embedding
from sns_np.surface import fit_mesh

SHARED = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "meshes")


def step_ms(report):
    """Milliseconds per step after the fit history's first record."""
    h = report.history
    return 1e3 * (h["seconds"][-1] - h["seconds"][0]) / (h["step"][-1] - h["step"][0])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--shared", default=SHARED, help="folder of the shared meshes")
    args = ap.parse_args(argv)
    if args.steps < 150:
        ap.error(f"--steps must be at least 150 (the history is recorded every 50), "
                 f"got {args.steps}")
    V, F = load(os.path.join(args.shared, "spot_triangulated.obj"))[:2]
    Vs = spherical_embedding(V, F, verbose=False)[0]
    times = {"area": [], "error": []}
    for _ in range(args.repeats):
        for mode in times:
            _, r = fit_mesh(V, F, Vs=Vs, steps=args.steps, sampling=mode, progress=False,
                            n_eval=100)
            times[mode].append(step_ms(r))
            print(f"{mode:>5}: {times[mode][-1]:.1f} ms per step", flush=True)
    area, error = np.median(times["area"]), np.median(times["error"])
    print(f"median: area {area:.1f} ms, error {error:.1f} ms, ratio error / area "
          f"{error / area:.2f}")


if __name__ == "__main__":
    main()
