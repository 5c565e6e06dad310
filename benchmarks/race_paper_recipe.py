"""Time to accuracy: sns_np's default fit against the paper's published recipe in PyTorch.

Run::

    python benchmarks/race_paper_recipe.py                 # spot, each side ~9 minutes
    python benchmarks/race_paper_recipe.py --seconds 60    # a short race (smoke test)
    python benchmarks/race_paper_recipe.py --save spot.npz # and keep sns_np's surface

Both sides start from one spherical embedding of the mesh (computed once here) and get the
same wall time on this CPU, one after the other (never at once: two heavy jobs on a 2-core
machine distort each other). sns_np runs ``fit_mesh`` with its defaults; the recipe runs in
its own process (``_torch_recipe.py``: RMSProp lr 1e-4 momentum 0.9, normal weight 1e-4,
PyTorch's default initialisation with the last layer at 1e-4, 2,048 surface samples plus a
block of 1,024 vertices per step). Each side's network is copied at the same training times
(geometric: 10, 20, 40, ... s and the end), and every copy is scored afterwards by one
evaluation (``fit_quality.mesh_fidelity``: two-sided mean distance relative to the bounding-box
diagonal, and the mean angle to the mesh's interpolated normal at the closest point).

Printed: both error curves, and for each of sns_np's snapshots the time the recipe needed to
reach both of its errors (or "> T" when it did not within the race), with the ratio. Where
the recipe does not get there, a power law fitted to its last snapshots (log error against
log time) gives an *estimate* of the time it would need, labelled as such.

Needs torch (``pip install torch``) and libigl; nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

from fit_quality import MESHES, SHARED, mesh_fidelity  # noqa: E402

from sns_np import SphericalNeuralSurface  # noqa: E402
from sns_np.mesh import check, load, spherical_embedding  # noqa: E402
from sns_np.nn import ResidualMLP  # noqa: E402
from sns_np.surface import fit_mesh  # noqa: E402


def snapshot_times(seconds):
    t, out = 10.0, []
    while t < seconds:
        out.append(t)
        t *= 2
    return out


def run_ours(V, F, Vs, times, seconds, seed):
    """sns_np's default fit, its network copied at the snapshot times (training clock)."""
    snaps, pending = {}, list(times)

    def copy(step, info):
        while pending and info["seconds"] >= pending[0]:
            snaps[pending.pop(0)] = (info["net"].astype(np.float64), step)

    S, report = fit_mesh(V, F, Vs=Vs, seed=seed, time_budget=seconds, progress=False,
                         callback=copy, history_every=5)
    snaps[report.seconds] = (S.net, report.steps)
    return S, report, snaps


def run_recipe(V, F, Vs, center, scale, times, seconds, seed, workdir):
    inputs, output = os.path.join(workdir, "in.npz"), os.path.join(workdir, "out.npz")
    np.savez(inputs, V=V, F=F, Vs=Vs, center=center, scale=scale, seconds=seconds,
             times=np.asarray(times), seed=seed)
    res = subprocess.run([sys.executable, os.path.join(HERE, "_torch_recipe.py"), inputs,
                          output], capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"the torch process failed:\n{res.stderr}")
    info = json.loads(res.stdout.strip().splitlines()[-1])
    snaps = {}
    with np.load(output) as d:
        for i, (t, steps) in enumerate(zip(d["times"], d["steps"])):
            net = ResidualMLP.zeros(width=256, depth=8)
            net.W0[...] = d[f"s{i}_0"]
            for k in range(8):
                net.W1[k][...] = d[f"s{i}_{1 + 2 * k}"]
                net.W2[k][...] = d[f"s{i}_{2 + 2 * k}"]
            net.W3[...] = d[f"s{i}_17"]
            snaps[float(t)] = (net, int(steps))
    return snaps, info


def score(snaps, center, scale, V, F):
    rows = []
    for t in sorted(snaps):
        net, steps = snaps[t]
        S = SphericalNeuralSurface(net, center=center, scale=scale)
        m = mesh_fidelity(S, V, F)
        rows.append({"t": t, "steps": steps, "dist": m["dist"], "nrm": m["nrm"]})
    return rows


def time_to_reach(rows, dist, nrm):
    for r in rows:
        if r["dist"] <= dist and r["nrm"] <= nrm:
            return r["t"]
    return None


def power_law_time(rows, key, target, last=3):
    """Time at which a power law through the last snapshots reaches ``target``; None when the
    error does not decrease."""
    pts = [(np.log(r["t"]), np.log(r[key])) for r in rows[-last:]]
    if len(pts) < 2:
        return None
    b, a = np.polyfit(*zip(*pts), 1)
    if b >= 0:
        return None
    return float(np.exp((np.log(target) - a) / b))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="spot", choices=sorted(MESHES))
    ap.add_argument("--seconds", type=float, default=None,
                    help="training seconds per side (default: sns_np's own budget for the "
                         "mesh, less the embedding)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save", metavar="MODEL",
                    help="also save sns_np's final surface (.npz), e.g. for a curvature map")
    args = ap.parse_args(argv)
    try:
        import igl  # noqa: F401
        import torch  # noqa: F401
    except ImportError as exc:
        sys.exit(f"race_paper_recipe.py needs torch and libigl: {exc}")

    V, F = load(os.path.join(SHARED, MESHES[args.mesh]))
    check(V, F)
    t = time.perf_counter()
    Vs = spherical_embedding(V, F, verbose=False)[0]
    t_embed = time.perf_counter() - t
    print(f"{args.mesh}: {len(V)} vertices, embedding {t_embed:.1f} s (shared by both sides)")

    seconds = args.seconds
    if seconds is None:          # what fit_mesh would give itself: its budget less the embedding
        from sns_np.surface.fit import AUTO
        seconds = AUTO["detailed"]["time_budget"] - t_embed
    times = snapshot_times(seconds)
    t = time.perf_counter()
    S, report, ours = run_ours(V, F, Vs, times, seconds, args.seed)
    print(f"sns_np: {report.steps} steps in {report.seconds:.0f} s "
          f"(wall {time.perf_counter() - t:.0f} s); chosen "
          + ", ".join(f"{k} {v['value']:.3g}" if isinstance(v["value"], float)
                      else f"{k} {v['value']}" for k, v in report.choices.items()))
    if args.save:
        S.save(args.save)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        theirs, info = run_recipe(V, F, Vs, S.center, S.scale, times, report.seconds,
                                  args.seed, tmp)
    print(f"recipe: torch {info['version']}, {info['threads']} threads, {info['steps']} steps "
          f"in {report.seconds:.0f} s of training (wall {time.perf_counter() - t:.0f} s)")

    ours_rows = score(ours, S.center, S.scale, V, F)
    their_rows = score(theirs, S.center, S.scale, V, F)
    print("\ntraining s | sns_np steps | sns_np dist | sns_np nrm deg | recipe steps | "
          "recipe dist | recipe nrm deg")
    for a, b in zip(ours_rows, their_rows):
        print(f"{a['t']:10.0f} | {a['steps']:12d} | {a['dist']:11.2e} | {a['nrm']:14.2f} | "
              f"{b['steps']:12d} | {b['dist']:11.2e} | {b['nrm']:14.2f}")

    T = their_rows[-1]["t"]
    print("\nthe recipe's time to reach sns_np's errors (both distance and normal):")
    for a in ours_rows:
        reach = time_to_reach(their_rows, a["dist"], a["nrm"])
        if reach is not None:
            print(f"  sns_np at {a['t']:5.0f} s ({a['dist']:.2e}, {a['nrm']:.2f} deg): recipe "
                  f"{reach:.0f} s, ratio {reach / a['t']:.1f}")
            continue
        est = [power_law_time(their_rows, "dist", a["dist"]),
               power_law_time(their_rows, "nrm", a["nrm"])]
        est_txt = ("estimate: never at its current rate" if None in est else
                   f"power-law estimate {max(est):.3g} s, ratio ~{max(est) / a['t']:.0f}")
        print(f"  sns_np at {a['t']:5.0f} s ({a['dist']:.2e}, {a['nrm']:.2f} deg): recipe "
              f"not within {T:.0f} s (ratio > {T / a['t']:.1f}); {est_txt}")


if __name__ == "__main__":
    main()
