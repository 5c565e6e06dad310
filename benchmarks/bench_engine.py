"""Engine benchmark: forward jets and the training step, as ratios measured in one run.

Run:  python benchmarks/bench_engine.py [--quick] [--no-torch]

For the reference network (width 256, depth 8, no biases) it prints, per dtype:

* the machine's matrix-product rate for the engine's own product shapes;
* full ``jet(order=2)`` at 4096 points: time, the same matrix products timed alone, their
  ratio (the engine's efficiency), the same jet on the threaded path (data-parallel chunks
  off, as with SNS_NP_DATA_PARALLEL=0), and the speed-up over PyTorch's fastest full Hessian;
* one training step of the reference loss at 2048 points (position MSE + 1e-4 normal error,
  gradient for all 1,050,112 parameters): time, and the speed-up over PyTorch's fastest
  variant;
* the order-2 training step of an analytic map's fit (the Hessian loss: directions
  ``[e_u, e_v, p]``, second derivatives along ``e_u, e_v``, 7 streams): time, its products
  alone, their ratio, and its cost relative to the order-1 step.
* float32 only: the step of a detailed mesh's fit (width 128, 512 points, the defaults of a
  detailed target): time, its products alone, their ratio, and the optimiser's update (Adam,
  SOAP with its change of bases every ten steps) beside it.

Targets (issue 2): efficiency >= 0.80 and >= 2.5x PyTorch for the full jet; training step
>= 1.3x PyTorch in float32 and >= 1.0x in float64. Nothing is asserted: the script prints.
The first call of every kernel (Numba compilation) is a warm-up and is never timed.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import _torch_reference as tref  # noqa: E402

from sns_np.nn import ResidualMLP, _engine, _parallel  # noqa: E402
from sns_np.surface.losses import hessian_loss, position_normal_loss  # noqa: E402


def best_time(fn, repeats=3):
    fn()  # warm-up: compilation, allocation, BLAS thread start
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


@contextlib.contextmanager
def threaded_path():
    """Switch the engine's data-parallel chunks off (as SNS_NP_DATA_PARALLEL=0 does)."""
    before = _parallel._enabled
    _parallel._enabled = False
    try:
        yield
    finally:
        _parallel._enabled = before


def sphere_frame(p):
    """Orthonormal tangent frame (n, 3, 2) with e_u x e_v = p (benchmark-local helper)."""
    a = np.where(np.abs(p[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    eu = np.cross(a, p)
    eu /= np.linalg.norm(eu, axis=1, keepdims=True)
    ev = np.cross(p, eu)
    return np.stack([eu, ev], axis=2)


def matmul_products_time(net, rows, dtype, repeats):
    """The jet's block products alone: 2 x depth products (rows, w) @ (w, w)."""
    A = np.random.default_rng(0).random((rows, net.width)).astype(dtype)
    B = np.empty_like(A)

    def run():
        for blk in range(net.depth):
            np.matmul(A, net.W1[blk].T, out=B)
            np.matmul(B, net.W2[blk].T, out=A)

    return best_time(run, repeats)


def training_matmul_time(net, n, S, dtype, repeats):
    """The training step's products alone: forward 2, backward 4 per block over n*S rows."""
    A = np.random.default_rng(0).random((n * S, net.width)).astype(dtype)
    B = np.empty_like(A)
    G = np.empty((net.width, net.width), dtype)

    def run():
        for blk in range(net.depth):
            np.matmul(A, net.W1[blk].T, out=B)
            np.matmul(B, net.W2[blk].T, out=A)
        for blk in range(net.depth):
            np.matmul(A.T, B, out=G)
            np.matmul(A, net.W2[blk], out=B)
            np.matmul(B.T, A, out=G)
            np.matmul(B, net.W1[blk], out=A)

    return best_time(run, repeats)


def torch_times(net, x, p, R, q, nt, repeats, chunks):
    """Run benchmarks/_torch_reference.py in its own process; None when torch is absent."""
    here = os.path.dirname(os.path.abspath(__file__))
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "inputs.npz")
        tref.write_inputs(path, net, x, p, R, q, nt, repeats, chunks)
        env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
        res = subprocess.run([sys.executable, os.path.join(here, "_torch_reference.py"), path],
                             capture_output=True, text=True, env=env)
    if res.returncode != 0:
        raise RuntimeError(f"the torch process failed:\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def detailed_step(g, repeats):
    """The step of a detailed mesh's fit (float32, width 128, 512 points, scale 40, SOAP):
    the network's step against its products alone, and the optimiser's update beside it.
    Small products leave the elementwise passes and the optimiser a larger share than at
    width 256, so this is where a fit's time goes."""
    from sns_np.nn.optim import SOAP, Adam
    from sns_np.surface.fit import _optimizer_options

    n, dtype = 512, np.float32
    net = ResidualMLP(width=128, depth=8, seed=0, input_scale=40, dtype=dtype)
    net.W3[...] = g.standard_normal(net.W3.shape).astype(dtype) / 16
    p = g.standard_normal((n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    R = sphere_frame(p).astype(dtype)
    q = (1.1 * p).astype(dtype)
    nt = p.astype(dtype)

    def step():
        def loss(y, JD, sl):
            val, dy, dJD, _ = position_normal_loss(y, JD, q[sl], nt[sl], n, 1.0)
            return val, dy, dJD
        return net.value_and_grad(p.astype(dtype), loss, order=1, directions=R)

    reps = 10 * repeats
    t_step = best_time(step, reps)
    t_mm = training_matmul_time(net, n, 3, dtype, reps)
    grad = step()[1]
    times = {}
    for name, opt in (("Adam", Adam(lr=1e-3)),
                      ("SOAP", SOAP(lr=1e-3, **_optimizer_options({"optimizer": "soap"},
                                                                 net)))):
        theta = net.pack()
        for _ in range(20):         # past the first change of basis
            opt.step(theta, grad)

        def ten(opt=opt, theta=theta):     # ten steps: one change of SOAP's bases
            for _ in range(10):
                opt.step(theta, grad)
        times[name] = best_time(ten, repeats) / 10
    print(f"detailed fit's step (width 128, {n} points, float32): {t_step * 1e3:6.1f} ms   "
          f"products alone {t_mm * 1e3:6.1f} ms   efficiency {t_mm / t_step:.2f}; "
          f"optimiser update: Adam {times['Adam'] * 1e3:.1f} ms, "
          f"SOAP {times['SOAP'] * 1e3:.1f} ms ({times['SOAP'] / t_step:.2f}x the network's)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, fewer torch variants")
    ap.add_argument("--no-torch", action="store_true", help="skip the PyTorch column")
    args = ap.parse_args(argv)
    repeats = 2 if args.quick else 3
    use_torch = importlib.util.find_spec("torch") is not None and not args.no_torch
    g = np.random.default_rng(0)
    n_jet, n_train = 4096, 2048
    status = "timed in its own process" if use_torch else "absent (column skipped)"
    print(f"sns_np engine benchmark: width 256, depth 8, {os.cpu_count()} cores; torch {status}")
    for dtype in (np.float64, np.float32):
        dt = np.dtype(dtype)
        net = ResidualMLP(seed=0, dtype=dtype)
        net.W3[...] = g.standard_normal(net.W3.shape) / 16  # an O(1) map, as after fitting
        x = g.standard_normal((n_jet, 3))
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        print(f"\n== {dt.name}")
        # the reference rate: the jet's products as one large call (the machine's
        # matrix-product rate, the target's reference), and repeated at the engine's own chunk
        # shape, where operands stay in cache (faster in float32: a stricter reference)
        rows = n_jet * 10
        t_big = matmul_products_time(net, rows, dtype, repeats)
        c = _engine.chunk_points(net, 10) * 10
        t_chunked = matmul_products_time(net, c, dtype, repeats) * rows / c
        flops = 2 * net.depth * 2 * rows * 256 * 256
        print(f"matrix-product rate (x 256 x 256): {flops / t_big / 1e9:.1f} GFLOP/s with "
              f"{rows} rows, {flops / t_chunked / 1e9:.1f} GFLOP/s with {c} rows (chunk)")
        for order, S in ((0, 1), (1, 4)):
            t = best_time(lambda order=order: net.jet(x, order), repeats)
            t_ref = matmul_products_time(net, n_jet * S, dtype, repeats)
            print(f"jet(order={order}) {n_jet} points: {t * 1e3:8.1f} ms   products alone "
                  f"{t_ref * 1e3:7.1f} ms   efficiency {t_ref / t:.2f}")
        t_jet = best_time(lambda: net.jet(x, 2), repeats)
        print(f"jet(order=2) {n_jet} points: {t_jet * 1e3:8.1f} ms   products alone "
              f"{t_big * 1e3:7.1f} ms   efficiency {t_big / t_jet:.2f}   (target >= 0.80); "
              f"against the chunk-shape products ({t_chunked * 1e3:.1f} ms) "
              f"{t_chunked / t_jet:.2f}")
        with threaded_path():
            t_thr = best_time(lambda: net.jet(x, 2), repeats)
        print(f"  the same jet on the threaded path (every product and pass on all threads, "
              f"chunk after chunk): {t_thr * 1e3:8.1f} ms   efficiency {t_big / t_thr:.2f}")
        R = sphere_frame(x)
        D = np.concatenate([R, x[:, :, None]], axis=2)
        t_dir = best_time(lambda: net.jet(x, 2, directions=D, second=2), repeats)
        print(f"jet(order=2, [e_u, e_v, p], second=2) (7 streams, geometry): "
              f"{t_dir * 1e3:8.1f} ms   ({t_jet / t_dir:.2f}x faster than the full jet)")

        # one training step at 2048 points
        p = g.standard_normal((n_train, 3))
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        R = sphere_frame(p)
        q = (p * np.array([1.0, 1.3, 0.7])).astype(dtype)
        nt = p / np.array([1.0, 1.3, 0.7])
        nt = (nt / np.linalg.norm(nt, axis=1, keepdims=True)).astype(dtype)

        def step():
            def loss(y, JD, sl):
                val, dy, dJD, _ = position_normal_loss(y, JD, q[sl], nt[sl], n_train, 1e-4)
                return val, dy, dJD
            return net.value_and_grad(p, loss, order=1, directions=R)

        t_step = best_time(step, repeats)
        t_mm_train = training_matmul_time(net, n_train, 3, dtype, repeats)
        with threaded_path():
            t_step_thr = best_time(step, repeats)
        print(f"training step {n_train} points: {t_step * 1e3:8.1f} ms   products alone "
              f"{t_mm_train * 1e3:7.1f} ms   efficiency {t_mm_train / t_step:.2f}   "
              f"(threaded path {t_step_thr * 1e3:.1f} ms)")

        # the order-2 step of the Hessian loss (fit_shape): 7 streams, the second-order rule
        D3 = np.concatenate([R, p[:, :, None]], axis=2)
        T2 = np.zeros((n_train, 3, 2, 2), dtype)

        def step2():
            def loss(y, JD3, D2D, sl):
                val, dy, dJD, _ = position_normal_loss(y, JD3[:, :, :2], q[sl], nt[sl],
                                                       n_train, 1e-4)
                val_h, dD2D, dJp, _ = hessian_loss(D2D, JD3[:, :, 2], T2[sl], n_train, 1e-3)
                dJD3 = np.concatenate([dJD, dJp[:, :, None]], axis=2)
                return val + val_h, dy, dJD3, dD2D
            return net.value_and_grad(p, loss, order=2, directions=D3, second=2)

        t_step2 = best_time(step2, repeats)
        t_mm_train2 = training_matmul_time(net, n_train, 7, dtype, repeats)
        print(f"training step, order 2 (Hessian loss, 7 streams) {n_train} points: "
              f"{t_step2 * 1e3:8.1f} ms   products alone {t_mm_train2 * 1e3:7.1f} ms   "
              f"efficiency {t_mm_train2 / t_step2:.2f}   ({t_step2 / t_step:.2f}x the order-1 "
              f"step)")
        if dt == np.float32:
            detailed_step(g, repeats)
        if use_torch:
            tt = torch_times(net, x, p, R, q, nt, repeats,
                             (256,) if args.quick else (128, 256, 512))
            hs, tr = tt["hessian"], tt["training"]
            name = min(hs, key=hs.get)
            print(f"PyTorch {tt['version']} ({tt['threads']} threads) fastest full Hessian: "
                  f"{hs[name] * 1e3:8.1f} ms ({name})   speed-up {hs[name] / t_jet:.2f}x   "
                  f"(target >= 2.5x)")
            name = min(tr, key=tr.get)
            target = 1.3 if dt == np.float32 else 1.0
            print(f"PyTorch fastest training step: {tr[name] * 1e3:8.1f} ms ({name})   "
                  f"speed-up {tr[name] / t_step:.2f}x   (target >= {target}x)")


if __name__ == "__main__":
    main()
