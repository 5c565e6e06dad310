"""Throughput of sns_np.batch: N small fits one after another in one process vs through a local
Dask cluster, and the cluster's per-task overhead in milliseconds.

    python benchmarks/batch_throughput.py            # N = 8, 200 steps of a 32 x 2 network
    python benchmarks/batch_throughput.py --n 16 --steps 400

The meshes are generated ellipsoids (icosphere level 2, 162 vertices, axes drawn from a seeded
generator), written to a temporary folder. Every fit has the same fixed budget: a step count,
and the options that would otherwise be measured on the mesh (learning rate, first-layer scale,
warm-up) given, so that both runs do exactly the same work. Both sides are warmed up first
(imports, Numba's compiled kernels loaded, one fit), and the cluster's start is timed apart:

* sequential: ``fit_mesh`` then ``save`` for each mesh in this process, with the BLAS and Numba
  threads it has by default (all the cores);
* batch: ``fit_many`` on a local cluster laid out by ``local_layout`` (processes x threads =
  cores), each fit on one thread.

Per-task overhead, three ways: the round trip of one no-op task (submit to result, median of
30, one at a time); the cost per task of 400 no-op tasks submitted at once (wall / 400); and,
from the batch itself, ``(batch wall x threads - sum of task seconds) / N``: what a shape costs
beyond its own fit. Prints the load average before and after: run it on an idle machine.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def _noop(i):
    return i


def _warm(options):
    """Import, load the compiled kernels and run one tiny fit (on a worker, or here)."""
    from sns_np.shapes import Ellipsoid
    from sns_np.surface import fit_mesh
    V, F = Ellipsoid(1.0, 1.1, 0.9).mesh(1)
    fit_mesh(V, F, **dict(options, steps=2), progress=False)
    return os.getpid()


def make_meshes(folder, n, level, seed=0):
    from sns_np.mesh import write_mesh
    from sns_np.shapes import Ellipsoid
    g = np.random.default_rng(seed)
    paths = []
    for i in range(n):
        a, b, c = g.uniform(0.6, 1.4, 3)
        p = Path(folder) / f"ellipsoid_{i:02d}.obj"
        write_mesh(p, *Ellipsoid(a, b, c).mesh(level))
        paths.append(p)
    return paths


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=8, help="number of meshes (8)")
    ap.add_argument("--steps", type=int, default=200, help="steps per fit (200)")
    ap.add_argument("--level", type=int, default=2, help="icosphere level of the meshes (2)")
    ap.add_argument("--workers", type=int, help="local worker processes (default: cores)")
    args = ap.parse_args(argv)

    import distributed

    from sns_np.batch import fit_many, local_layout
    from sns_np.mesh import load
    from sns_np.surface import fit_mesh
    options = dict(width=32, depth=2, batch=512, steps=args.steps, lr=1e-3, input_scale=4.0,
                   warmup=20, n_eval=2000)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = make_meshes(tmp, args.n, args.level)

        _warm(options)
        t0 = time.perf_counter()
        seq_times = []
        (tmp / "seq").mkdir()
        for p in paths:
            t = time.perf_counter()
            S, _ = fit_mesh(*load(p), progress=False, **options)
            S.save(tmp / "seq" / f"{p.stem}.npz")
            seq_times.append(time.perf_counter() - t)
        seq = time.perf_counter() - t0

        n_proc, threads = local_layout(args.workers)
        t0 = time.perf_counter()
        with distributed.LocalCluster(n_workers=n_proc, threads_per_worker=threads,
                                      processes=True, host="127.0.0.1",
                                      dashboard_address=":0") as cluster, \
                distributed.Client(cluster) as client:
            client.wait_for_workers(n_proc)
            start = time.perf_counter() - t0
            client.run(_warm, options)                      # every worker, as above

            rtt = []
            for i in range(30):
                t = time.perf_counter()
                client.submit(_noop, i, pure=False).result()
                rtt.append(time.perf_counter() - t)
            t = time.perf_counter()
            client.gather(client.map(_noop, range(400), pure=False))
            per_task_bulk = (time.perf_counter() - t) / 400

            t0 = time.perf_counter()
            table = fit_many(paths, tmp / "batch", client=client, progress=False, **options)
            batch = time.perf_counter() - t0
        statuses = set(table.column("status"))
        task_sum = sum(table.column("seconds"))
        total_threads = n_proc * threads
    load_after = os.getloadavg()

    per_shape_seq = seq / args.n
    overhead_batch = (batch * total_threads - task_sum) / args.n
    print(f"sns_np batch throughput: N = {args.n} ellipsoids (icosphere level {args.level}), "
          f"{args.steps} steps of a 32 x 2 network, batch 512")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} "
          f"(cores {os.cpu_count()})")
    print(f"sequential, one process:  {seq:7.2f} s  ({per_shape_seq:.2f} s per shape; "
          f"median {statistics.median(seq_times):.2f} s)")
    print(f"local cluster start:      {start:7.2f} s  ({n_proc} processes x {threads} threads; "
          f"not counted below)")
    print(f"batch (fit_many):         {batch:7.2f} s  (statuses {sorted(statuses)}; task "
          f"median {statistics.median(table.column('seconds')):.2f} s)")
    print(f"ratio sequential / batch: {seq / batch:7.2f}")
    print(f"per-task overhead: round trip of a no-op {statistics.median(rtt) * 1e3:.1f} ms "
          f"(median of 30); {per_task_bulk * 1e3:.2f} ms per no-op task in bulk (400); "
          f"{overhead_batch * 1e3:.0f} ms per shape in the batch beyond its fit "
          f"(wall x threads - sum of task times, / N)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
