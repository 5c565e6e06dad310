"""Spectral accuracy: Rayleigh-Ritz (and optionally neural) eigenvalues against cotangent FEM.

Run::

    python benchmarks/spectral_accuracy.py                          # Ellipsoid(1, 1.3, 0.7)
    python benchmarks/spectral_accuracy.py --shape sphere -k 15
    python benchmarks/spectral_accuracy.py --model spot.npz -k 10 --levels 4 5 6
    python benchmarks/spectral_accuracy.py --neural 3               # also the paper's method

For a surface map (an analytic shape or a fitted SphericalNeuralSurface ``--model``) it prints

* the Rayleigh-Ritz eigenvalues, the harmonic degree ``L`` chosen, the convergence indicator
  (relative change from ``L - 2`` to ``L``) and the time;
* cotangent-FEM eigenvalues of the icosphere of each ``--levels`` pushed through the map, their
  relative difference to Ritz and the observed convergence order between levels;
* the Richardson extrapolation of the two finest levels (``h^2``) and its difference to Ritz;
* with ``--neural m``: the first ``m`` eigenvalues of the neural method, their Monte Carlo
  standard errors and the time.

Nothing is asserted; the tests assert the thresholds of issue 5. Timings on a shared machine are
noisy; compare them within one run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from sns_np.spectral import eigenmodes, fem_eigenvalues, richardson  # noqa: E402

SHAPES = {
    "sphere": lambda: __import__("sns_np.shapes", fromlist=["Sphere"]).Sphere(),
    "ellipsoid": lambda: __import__("sns_np.shapes", fromlist=["Ellipsoid"]).Ellipsoid(
        1.0, 1.3, 0.7),
    "perturbed": lambda: __import__("sns_np.shapes",
                                    fromlist=["PerturbedEllipsoid"]).PerturbedEllipsoid(),
}


def load_surface(args):
    if args.model:
        from sns_np.surface import SphericalNeuralSurface
        return SphericalNeuralSurface.load(args.model), f"model {args.model}"
    if args.shape in SHAPES:
        return SHAPES[args.shape](), args.shape
    from sns_np.shapes import radial_shape
    return radial_shape(args.shape), args.shape


def row(label, values, fmt=".7g"):
    return f"{label:<22s}" + "".join(format(v, ">11" + fmt) for v in values)


def rel_row(label, values):
    return f"{label:<22s}" + "".join(format(v, ">+11.2e") for v in values)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--model", help="a SphericalNeuralSurface .npz file")
    src.add_argument("--shape", default="ellipsoid",
                     help="sphere, ellipsoid (1, 1.3, 0.7), perturbed, or a radial shape name "
                          "(flower, bobble, spike, tree)")
    ap.add_argument("-k", type=int, default=10, help="number of non-zero eigenvalues")
    ap.add_argument("--levels", type=int, nargs="+", default=[4, 5, 6],
                    help="icosphere levels of the FEM reference")
    ap.add_argument("--L", type=int, default=None, help="harmonic degree (default: automatic)")
    ap.add_argument("--L-max", type=int, default=40)
    ap.add_argument("--tol", type=float, default=1e-6, help="Ritz convergence target")
    ap.add_argument("--neural", type=int, default=0, metavar="M",
                    help="also run the neural method for the first M modes")
    ap.add_argument("--steps", type=int, default=None, help="neural steps per mode")
    args = ap.parse_args(argv)

    surface, name = load_surface(args)
    print(f"surface: {name}, k = {args.k}")

    t0 = time.perf_counter()
    res = eigenmodes(surface, args.k, method="ritz", L=args.L, L_max=args.L_max, tol=args.tol)
    t_ritz = time.perf_counter() - t0
    print(f"\nRayleigh-Ritz: L = {res.info['L']} ({res.info['n_basis']} harmonics, "
          f"{res.info['n_points']} quadrature nodes), indicator {res.convergence:.2e}, "
          f"converged {res.converged}, {t_ritz:.2f} s, area {res.area:.8g}")
    ritz = res.eigenvalues
    print(row("i", range(1, args.k + 1), fmt="d"))
    print(row("ritz", ritz))

    fem = {}
    print("\ncotangent FEM on the icosphere pushed through the map (consistent mass):")
    for lev in sorted(args.levels):
        t0 = time.perf_counter()
        fem[lev] = fem_eigenvalues(surface, args.k, lev)
        dt = time.perf_counter() - t0
        rel = (fem[lev] - ritz) / ritz
        print(row(f"level {lev} ({dt:.1f} s)", fem[lev]))
        print(rel_row("  rel. diff. to ritz", rel))
    levels = sorted(fem)
    for a, b in zip(levels, levels[1:]):
        ea, eb = np.abs(fem[a] - ritz), np.abs(fem[b] - ritz)
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = np.log2(ea / eb)
        print(row(f"  order {a}->{b}", rate, fmt=".3f"))
    if len(levels) >= 2:
        ext = richardson(fem[levels[-2]], fem[levels[-1]])
        print(row(f"richardson {levels[-2]},{levels[-1]}", ext))
        print(rel_row("  rel. diff. to ritz", (ext - ritz) / ritz))
        print(f"\nmax |ritz - FEM level {levels[-1]}| / ritz = "
              f"{np.max(np.abs(fem[levels[-1]] - ritz) / ritz):.2e};  "
              f"max |ritz - richardson| / ritz = {np.max(np.abs(ext - ritz) / ritz):.2e}")

    if args.neural:
        m = min(args.neural, args.k)
        opts = {} if args.steps is None else {"steps": args.steps}
        t0 = time.perf_counter()
        nres = eigenmodes(surface, m, method="neural", rng=0, **opts)
        dt = time.perf_counter() - t0
        print(f"\nneural (paper Sec. 5), {m} modes, {dt:.1f} s:")
        print(row("neural", nres.eigenvalues))
        print(row("  std. error", nres.stderr, fmt=".2e"))
        print(rel_row("  rel. diff. to ritz", (nres.eigenvalues - ritz[:m]) / ritz[:m]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
