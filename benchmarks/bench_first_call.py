"""First-call cost of the derivative engine (Numba compilation), with a cold and a warm cache.

Every measurement is a fresh Python process, as a user's first call is:

* cold: an empty Numba cache (``NUMBA_CACHE_DIR`` points at a new temporary folder, so every
  kernel is compiled from scratch; the package's own ``__pycache__`` is left alone);
* warm: the same call in a new process with that folder now filled (kernels loaded from disk).

Two calls, each in its own process (so neither inherits the other's compiled kernels):

* ``jet``: the first ``net.jet(p, order=2)`` of the reference network (256 x 8, float64) at
  1,000 sphere points;
* ``step``: the first training step as fitting takes it: ``net.value_and_grad`` of a
  position + tangent-Jacobian loss, float32, 2,048 points (the default batch), directions the
  tangent frame.

Printed per run: the import of ``sns_np.nn``, the first call, a second call (the compute
alone) and their difference (the one-off cost). Run from the project root:

    python benchmarks/bench_first_call.py             # 2 cold/warm pairs per call
    python benchmarks/bench_first_call.py --repeat 3
    python benchmarks/bench_first_call.py --source ../old_checkout     # compare

Figures: docs/performance.md ("First call").
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

CHILD = r"""
import json, os, sys, time
src = os.environ.get("SNS_NP_BENCH_SOURCE")
if src:   # another checkout: bypass an editable install's import hook
    sys.meta_path[:] = [f for f in sys.meta_path if "__editable__" not in repr(f)]
    sys.path.insert(0, src)
t0 = time.perf_counter()
import numpy as np
import sns_np
from sns_np.nn import ResidualMLP
t_import = time.perf_counter() - t0
which = sys.argv[1]
rng = np.random.default_rng(0)
if which == "jet":
    p = rng.standard_normal((1000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    net = ResidualMLP(width=256, depth=8, seed=0)
    call = lambda: net.jet(p, order=2)
else:
    from sns_np.geometry import tangent_frame
    p = rng.standard_normal((2048, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    R = tangent_frame(p).astype(np.float32)
    p = p.astype(np.float32)
    net = ResidualMLP(width=256, depth=8, seed=0, dtype=np.float32)

    def loss(y, JR, sl):
        n = len(p)
        r = y - p[sl]
        return float((r ** 2).sum() + (JR ** 2).sum()) / n, 2 * r / n, 2 * JR / n

    call = lambda: net.value_and_grad(p, loss, order=1, directions=R)
t = time.perf_counter(); call(); first = time.perf_counter() - t
t = time.perf_counter(); call(); again = time.perf_counter() - t
print(json.dumps(dict(import_s=t_import, first_s=first, again_s=again, file=sns_np.__file__)))
"""


def run_child(which, cache_dir, source=None):
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    if source:
        env["SNS_NP_BENCH_SOURCE"] = os.path.abspath(source)
    out = subprocess.run([sys.executable, "-c", CHILD, which], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=2,
                        help="cold/warm pairs per call (default: %(default)s)")
    parser.add_argument("--source", metavar="DIR",
                        help="import sns_np from this folder (e.g. an older checkout's root, "
                             "to compare) instead of the installed package")
    args = parser.parse_args(argv)
    print(f"{'call':<5} {'cache':<5} {'import':>7} {'first':>7} {'second':>7} {'one-off':>8}"
          f"   (seconds)")
    best = {}
    source = None
    for which in ("jet", "step"):
        for _ in range(args.repeat):
            with tempfile.TemporaryDirectory(prefix="sns_np_numba_") as cache:
                for kind in ("cold", "warm"):
                    r = run_child(which, cache, args.source)
                    source = r["file"]
                    print(f"{which:<5} {kind:<5} {r['import_s']:7.2f} {r['first_s']:7.2f} "
                          f"{r['again_s']:7.2f} {r['first_s'] - r['again_s']:8.2f}")
                    key = (which, kind)
                    best[key] = min(best.get(key, float("inf")), r["first_s"])
    print(f"sns_np from {os.path.dirname(source)}")
    for which, label in (("jet", "jet(order=2), 256 x 8 float64, 1,000 points"),
                         ("step", "training step, 256 x 8 float32, 2,048 points")):
        print(f"first {label}: cold {best[which, 'cold']:.2f} s, warm "
              f"{best[which, 'warm']:.2f} s (best of {args.repeat})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
