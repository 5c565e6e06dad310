"""Fitting quality and time on the shared meshes (the figures of issue 4 and docs/fitting.md).

Run::

    python benchmarks/fit_quality.py spot                 # default fit of spot_triangulated
    python benchmarks/fit_quality.py max --width 384 --time-budget 900
    python benchmarks/fit_quality.py armadillo --width 384 --time-budget 900
    python benchmarks/fit_quality.py dtype --steps 600    # float32 vs float64 training
    python benchmarks/fit_quality.py init --steps 600     # ridge read-out vs random init

Mesh cases fit ``../shared/data/meshes/<file>`` with the library's defaults (overridable on the
command line) and print the embedding time, the fit time and the held-out errors: position
error relative to the bounding-box diagonal and the angle to the mesh's interpolated normals,
at 20,000 sphere points not used for training. ``--out DIR`` keeps the models (e.g. for
``spectral_accuracy.py --model``).

``dtype`` and ``init`` fit the analytic Ellipsoid(1, 1.3, 0.7) twice with the same seed and
budget, changing only the training precision or the initialisation, and compare with the
closed forms (normal angle, relative error of H). Nothing is asserted; timings on a shared
machine are noisy, so compare them within one run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from sns_np.mesh import check, load, spherical_embedding  # noqa: E402
from sns_np.sampling import uniform_sphere  # noqa: E402
from sns_np.surface import fit_mesh, fit_shape  # noqa: E402

MESHES = {"spot": "spot_triangulated.obj", "max": "max10606.obj",
          "armadillo": "armadillo21622.obj", "ellipsoid": None}
SHARED = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data",
                      "meshes")


def fit_options(args):
    keys = ("width", "depth", "steps", "batch", "time_budget", "dtype", "lr", "input_scale",
            "normal_weight")
    return {k: getattr(args, k) for k in keys if getattr(args, k) is not None}


def mesh_case(args):
    t0 = time.perf_counter()
    if MESHES[args.case] is None:
        from sns_np.shapes import Ellipsoid
        V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(4)
        name = "Ellipsoid(1, 1.3, 0.7) level 4"
    else:
        V, F = load(os.path.join(args.shared, MESHES[args.case]))[:2]
        name = MESHES[args.case]
    check(V, F)
    Vs, emb = spherical_embedding(V, F, verbose=False)
    t_emb = time.perf_counter() - t0
    S, rep = fit_mesh(V, F, Vs=Vs, check=False, progress=not args.quiet, **fit_options(args))
    o = rep.options
    print(f"{name}: {len(V)} vertices; embedding {t_emb:.1f} s ({emb.flipped_after} flipped); "
          f"network {o['width']} x {o['depth']}, batch {o['batch']}, {o['dtype']}")
    print(f"  fit: {rep.steps} steps in {rep.seconds:.1f} s ({rep.stopped}), "
          f"{rep.seconds / max(rep.steps, 1) * 1e3:.0f} ms/step")
    print(f"  held-out position error: mean {rep.position_relative:.2e}, RMS "
          f"{rep.position_rms / rep.bbox_diagonal:.2e}, max "
          f"{rep.position_max / rep.bbox_diagonal:.2e} of the bbox diagonal")
    print(f"  held-out normal error: mean {rep.normal_mean_deg:.3f} deg, max "
          f"{rep.normal_max_deg:.2f} deg")
    dist = distance_to_mesh(S, V, F)
    if dist is not None:
        print(f"  distance from the surface to the mesh (libigl): mean {dist.mean():.2e}, "
              f"median {np.median(dist):.2e}, 95th percentile {np.percentile(dist, 95):.2e} "
              f"of the bbox diagonal")
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        path = S.save(os.path.join(args.out, f"{args.case}.npz"))
        print(f"  model: {path}")


def distance_to_mesh(S, V, F, n=20000):
    """Distance of S at n held-out sphere points to the mesh surface, relative to the bbox
    diagonal (None without libigl). Unlike the position error, it ignores tangential sliding
    of the parametrisation: it measures the shape only."""
    try:
        import igl
    except ImportError:
        return None
    p = uniform_sphere(n, rng=5)
    d2 = igl.point_mesh_squared_distance(S(p), np.asarray(V, np.float64),
                                         np.asarray(F, np.int64))[0]
    return np.sqrt(d2) / np.linalg.norm(V.max(axis=0) - V.min(axis=0))


def ellipsoid_errors(S, n=20000):
    from sns_np.demo import ellipsoid_foot_point, ellipsoid_geometry
    from sns_np.geometry import differential_quantities
    p = uniform_sphere(n, rng=2024)
    dq = differential_quantities(S, p)
    n_ref, H_ref, _ = ellipsoid_geometry(ellipsoid_foot_point(dq.x))
    ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", dq.n, n_ref), -1, 1)))
    return ang.mean(), np.abs(dq.H - H_ref).mean() / np.abs(H_ref).mean()


def comparison_case(args):
    from sns_np.shapes import Ellipsoid
    shape = Ellipsoid(1.0, 1.3, 0.7)
    opts = fit_options(args)
    variants = ({"dtype": "float32"}, {"dtype": "float64"}) if args.case == "dtype" else \
        ({"init": "ridge"}, {"init": "random"})
    opts.setdefault("steps", 600)
    print(f"Ellipsoid(1, 1.3, 0.7), fit_shape, {opts}")
    for v in variants:
        S, rep = fit_shape(shape, progress=not args.quiet, **{**opts, **v})
        ang, h_err = ellipsoid_errors(S)
        curve = ", ".join(f"{int(s)}: {r:.1e}" for s, r in
                          zip(rep.history["step"][::4], rep.history["position_rms"][::4]))
        print(f"  {v}: {rep.steps} steps in {rep.seconds:.1f} s "
              f"({rep.seconds / rep.steps * 1e3:.0f} ms/step); normal error {ang:.3f} deg, "
              f"H error {100 * h_err:.2f}%, position RMS {rep.position_rms:.2e}")
        print(f"    running position RMS by step: {curve}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=[*MESHES, "dtype", "init"])
    ap.add_argument("--width", type=int)
    ap.add_argument("--depth", type=int)
    ap.add_argument("--steps", type=int)
    ap.add_argument("--batch", type=int)
    ap.add_argument("--lr", type=float)
    ap.add_argument("--time-budget", type=float)
    ap.add_argument("--dtype", choices=["float32", "float64"])
    ap.add_argument("--input-scale", type=float, help="first-layer scale of the initialisation")
    ap.add_argument("--normal-weight", type=float)
    ap.add_argument("--out", help="folder for the fitted models")
    ap.add_argument("--shared", default=SHARED, help="folder of the shared meshes")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    if args.case in ("dtype", "init"):
        comparison_case(args)
    else:
        mesh_case(args)


if __name__ == "__main__":
    main()
