"""Training steps on a network with far-negative units cost what a fresh network's do.

A fit drives some hidden units far negative (the FLOWER fit, docs/performance.md): their
sigmoids are tiny, and in float32 the products of such sigmoids along the layers used to be
subnormal numbers, on which the matrix products and the Adam update run several times slower.
This benchmark builds such a network without a fit: a fresh 256 x 8 float32 network at the
detailed first-layer scale (40), then a fifth of the inner units of every block given weights
that put their pre-activations between about -70 and -35 at every point. It times a training
step (``value_and_grad`` of the position + normal loss on 512 points, then an Adam step) on
both networks, alternately, and prints the ratio (1.0: no subnormal penalty).

It reproduces a milder form of the effect than the FLOWER network: on the project's machine
1.11 before the float32 flush (commit 0308ada) and 1.01 after it, where the FLOWER network's
gradient took 2.3 times a fresh one's before (docs/performance.md).

Run::

    python benchmarks/bench_subnormal.py [--repeats 20]

Nothing is asserted; measure on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from sns_np.geometry import tangent_frame  # noqa: E402
from sns_np.nn import Adam, ResidualMLP  # noqa: E402
from sns_np.nn.activations import softplus  # noqa: E402
from sns_np.sampling import uniform_sphere  # noqa: E402
from sns_np.surface import position_normal_loss  # noqa: E402


def far_negative(net, p, fraction=0.2, band=(-65.0, -40.0), seed=1):
    """A copy of ``net`` in which ``fraction`` of the inner units of every block have
    pre-activations in ``band`` (on average over ``p``) at every point of ``p``."""
    out = net.copy()
    g = np.random.default_rng(seed)
    h = softplus(p @ out.W0.T.astype(np.float64))
    k = int(fraction * out.width)
    for blk in range(out.depth):
        units = g.choice(out.width, k, replace=False)
        # negative rows: with positive features the pre-activation is negative everywhere
        rows = -np.abs(g.standard_normal((k, out.width)))
        u = h @ rows.T
        rows *= (g.uniform(*band, k) / u.mean(axis=0))[:, None]
        out.W1[blk][units] = rows.astype(out.dtype)
        W1, W2 = out.W1[blk].astype(np.float64), out.W2[blk].astype(np.float64)
        h = softplus(h + softplus(h @ W1.T) @ W2.T)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args(argv)
    g = np.random.default_rng(0)
    p = uniform_sphere(512, g)
    pc, R = p.astype(np.float32), tangent_frame(p).astype(np.float32)
    q = p.astype(np.float32) * 1.1
    nt = p.astype(np.float32)

    def loss_fn(y, JD, sl):
        v, dy, dJD, _ = position_normal_loss(y, JD, q[sl], nt[sl], len(p), 1.0)
        return v, dy, dJD

    fresh = ResidualMLP(width=256, depth=8, seed=0, dtype=np.float32, input_scale=40.0)
    nets = {"fresh": fresh, "far-negative": far_negative(fresh, p)}
    times = {name: [] for name in nets}
    for net in nets.values():                            # compile and warm up
        net.value_and_grad(pc, loss_fn, order=1, directions=R)
    opts = {name: Adam(lr=1e-6) for name in nets}
    for _ in range(args.repeats):
        for name, net in nets.items():                   # alternate: the same conditions
            t = time.perf_counter()
            _, grad = net.value_and_grad(pc, loss_fn, order=1, directions=R)
            opts[name].step(net.theta, grad)
            times[name].append(time.perf_counter() - t)
    med = {name: float(np.median(v)) for name, v in times.items()}
    for name in nets:
        print(f"{name:>13}: {med[name] * 1e3:6.1f} ms per training step (median of "
              f"{args.repeats})")
    print(f"ratio far-negative / fresh: {med['far-negative'] / med['fresh']:.2f}")


if __name__ == "__main__":
    main()
