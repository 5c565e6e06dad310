"""Run every example in order and check that each wrote its output; exit 1 if any failed.

The examples form a small pipeline on the built-in ellipsoid: fit_mesh.py fits and saves a
model, curvature_map.py renders its curvature, compare_to_mesh.py compares it with the mesh.
gallery.py then runs in its quick mode (a small ellipsoid fit, seconds; the full gallery of
docs/gallery.md fits spot for about 9 minutes and is run by hand). Each runs in its own Python
process, as a user would run it.

    SNS_NP_SMOKE=1 python examples/run_all.py     # tiny budgets: under a minute
    python examples/run_all.py --out-dir out      # full budgets (minutes), keep the outputs

``tox -e examples`` runs the first line. Without --out-dir the outputs go to a temporary
folder that is removed at the end.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: (script, extra arguments, files it must write into the output folder)
EXAMPLES = [
    ("fit_mesh.py", [], ["ellipsoid.npz"]),
    ("curvature_map.py", [], ["ellipsoid_curvature.png"]),
    ("compare_to_mesh.py", [], ["ellipsoid_compare.json"]),
    ("gallery.py", ["--quick"], ["gallery_spot_mean_curvature.png", "gallery_eigenmodes.png",
                                 "gallery_heat_flow.png", "gallery_mcf.png"]),
]


def run_one(script, extra, expected, out_dir, timeout):
    """Run one example; returns (ok, seconds, reason)."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONUNBUFFERED="1")   # keep output in order
    cmd = [sys.executable, str(HERE / script), "--out-dir", str(out_dir), *extra]
    print(f"\n=== {script} {' '.join(extra)}", flush=True)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, time.perf_counter() - t0, f"timed out after {timeout:.0f} s"
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        return False, seconds, f"exit status {proc.returncode}"
    missing = [name for name in expected if not (out_dir / name).is_file()]
    if missing:
        return False, seconds, f"did not write {', '.join(missing)}"
    return True, seconds, ""


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="run_all.py", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out-dir", help="keep the outputs in this folder")
    parser.add_argument("--timeout", type=float, default=None,
                        help="seconds allowed per example (default 120 in smoke mode, else "
                             "3600)")
    args = parser.parse_args(argv)
    smoke = os.environ.get("SNS_NP_SMOKE", "0") not in ("", "0")
    timeout = args.timeout or (120.0 if smoke else 3600.0)
    print(f"running {len(EXAMPLES)} examples ({'smoke mode' if smoke else 'full budgets'})")

    with tempfile.TemporaryDirectory(prefix="sns_np_examples_") as tmp:
        out_dir = Path(args.out_dir) if args.out_dir else Path(tmp)
        out_dir.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        results = [(script, *run_one(script, extra, expected, out_dir, timeout))
                   for script, extra, expected in EXAMPLES]
        total = time.perf_counter() - t0

    print("\nsummary:")
    for script, ok, seconds, reason in results:
        print(f"  {'ok  ' if ok else 'FAIL'}  {script:<22} {seconds:6.1f} s  {reason}")
    failed = [script for script, ok, _, _ in results if not ok]
    print(f"{len(results) - len(failed)} of {len(results)} examples passed in {total:.1f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
