"""Fit four shared meshes through the batch and compare their spectra (ShapeDNA).

What it shows: sns_np.batch on a real collection. Two shapes, each meshed two ways:
spot_triangulated / spot_quadrangulated (the same 2,930 vertices, triangles vs quads) and
max10606 / decimated_max (the same bust, a fine and a bad-quality decimation). All four are
fitted through ``fit_many`` on a local Dask cluster, then the first K Laplace-Beltrami
eigenvalues of each fitted surface come from ``spectra_many`` (Rayleigh-Ritz), and those of
each mesh itself from cotangent FEM. Spectra are compared after scaling to area 4 pi
(lambda * A / (4 pi): ShapeDNA's normalisation, so that a uniform scale does not count), and
the script reports whether the neural spectra of one shape meshed two ways agree more closely
than the FEM spectra do: the paper's claim of robustness to meshing, measured whatever the
outcome.

Run (from the project root; needs pip install "sns-np[distributed,plots]"):

    python examples/batch_shared_meshes.py                     # default fits: ~10 min each
    python examples/batch_shared_meshes.py --steps 4000 --max-degree 56  # docs/batch.md
    python examples/batch_shared_meshes.py --scheduler tcp://host:8786

The fits take the library's defaults (sns_np.surface.FitOptions) unless options are given;
--time-budget shortens each fit (--help shows the automatic budget of a detailed mesh).
Rerunning skips the fits already complete.
SNS_NP_SMOKE=1 fits a 32 x 2 network for 50 steps (seconds) and uses K = 5.
Output in OUT_DIR (default ./sns_np_examples_out/batch): the four models, summary.csv/.json,
spectra_neural.csv/.json, spectra_fem.csv/.json, comparison.json and spectra.png.
"""

import argparse
import json
import math
import sys
from pathlib import Path

from _common import SMOKE, SMOKE_FIT, clear_errors, positive_int, write_atomically

from sns_np.options import FitOptions, add_arguments, given_arguments

MESHES = ["spot_triangulated", "spot_quadrangulated", "max10606", "decimated_max"]
PAIRS = [("spot_triangulated", "spot_quadrangulated"), ("max10606", "decimated_max")]
DEFAULT_MESH_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes"
#: the fitting options this example offers (flags, help and defaults come from FitOptions)
FIT_FLAGS = ("time_budget", "steps", "width", "depth")


def fem_table(paths, k):
    """Cotangent FEM eigenvalues of each mesh itself (sns_np.spectral.mesh_eigenvalues)."""
    import time

    from sns_np.batch import Table
    from sns_np.mesh import load, surface_area
    from sns_np.spectral import mesh_eigenvalues
    rows = []
    for p in paths:
        t0 = time.perf_counter()
        V, F = load(p)
        lam = mesh_eigenvalues(V, F, k)
        row = {"name": p.stem, "seconds": time.perf_counter() - t0,
               "area": float(surface_area(V, F)), "n_vertices": len(V)}
        row.update({f"lambda_{i}": float(v) for i, v in enumerate(lam, start=1)})
        rows.append(row)
    return Table(rows, meta={"method": "cotangent FEM, consistent mass matrix", "k": k})


def normalised(row, k):
    """Eigenvalues scaled to area 4 pi: lambda * A / (4 pi)."""
    return [row[f"lambda_{i}"] * row["area"] / (4 * math.pi) for i in range(1, k + 1)]


def compare(neural, fem, k):
    """Relative differences of the two meshings of each shape, neural and FEM."""
    by = {"neural": {r["name"]: r for r in neural}, "fem": {r["name"]: r for r in fem}}
    out = {}
    for a, b in PAIRS:
        entry = {}
        for method in ("neural", "fem"):
            ra, rb = by[method].get(a), by[method].get(b)
            if ra is None or rb is None or ra.get("lambda_1") is None \
                    or rb.get("lambda_1") is None:
                entry[method] = None
                continue
            la, lb = normalised(ra, k), normalised(rb, k)
            rel = [abs(x - y) / (0.5 * (x + y)) for x, y in zip(la, lb)]
            entry[method] = {"mean_relative_difference": sum(rel) / k,
                             "max_relative_difference": max(rel), "per_eigenvalue": rel,
                             "area": [ra["area"], rb["area"]]}
        n, f = entry["neural"], entry["fem"]
        entry["neural_agrees_more_closely"] = (
            None if n is None or f is None
            else n["mean_relative_difference"] < f["mean_relative_difference"])
        out[f"{a} vs {b}"] = entry
    return out


def plot(neural, fem, k, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    by = {"neural": {r["name"]: r for r in neural}, "FEM": {r["name"]: r for r in fem}}
    for ax, (a, b) in zip(axes, PAIRS):
        for name, colour in ((a, "C0"), (b, "C1")):
            for method, style in (("neural", "-o"), ("FEM", "--x")):
                r = by[method].get(name)
                if r is None or r.get("lambda_1") is None:
                    continue
                ax.plot(range(1, k + 1), normalised(r, k), style, color=colour, ms=3,
                        label=f"{name} ({method})")
        ax.set_xlabel("index i")
        ax.set_ylabel("lambda_i x area / (4 pi)")
        ax.set_title(f"{a.split('_')[0] if a.startswith('spot') else 'max'}: two meshings")
        ax.legend(fontsize=7)

    def write(tmp):
        fig.savefig(tmp, dpi=120, format="png")

    write_atomically(path, write)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="batch_shared_meshes.py", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh-dir", default=str(DEFAULT_MESH_DIR),
                        help="folder of the shared meshes (%(default)s)")
    parser.add_argument("--out-dir", default="sns_np_examples_out/batch",
                        help="output folder (%(default)s)")
    parser.add_argument("-k", type=positive_int, default=None,
                        help="eigenvalues per shape (default 20; 5 with SNS_NP_SMOKE=1)")
    add_arguments(parser, FitOptions, FIT_FLAGS)
    parser.add_argument("--max-degree", type=positive_int, default=40,
                        help="largest harmonic degree of the Rayleigh-Ritz spectra (40)")
    parser.add_argument("--workers", type=positive_int, help="local worker processes")
    parser.add_argument("--scheduler", help="address of a running Dask scheduler")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    with clear_errors(parser):
        from sns_np.batch import fit_many, spectra_many
        mesh_dir = Path(args.mesh_dir)
        paths = [mesh_dir / f"{m}.obj" for m in MESHES]
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            raise ValueError(f"shared meshes not found: {', '.join(missing)} (--mesh-dir)")
        k = args.k or (5 if SMOKE else 20)
        options = dict(SMOKE_FIT) if SMOKE else {}
        options.update(given_arguments(args, FIT_FLAGS))
        out = Path(args.out_dir)
        out.mkdir(parents=True, exist_ok=True)
        cluster = dict(scheduler=args.scheduler, workers=args.workers)
        fits = fit_many(paths, out, progress=not args.quiet, **cluster, **options)
        print(fits.format(["name", "status", "steps", "fit_seconds", "position_relative",
                           "normal_mean_deg", "message"]))
        models = [r["output"] for r in fits if r["status"] != "error"]
        neural = spectra_many(models, k, out=out / "spectra_neural.csv",
                              progress=not args.quiet, L_max=args.max_degree, **cluster)
        fem = fem_table(paths, k)
        fem.to_csv(out / "spectra_fem.csv")
        fem.to_json(out / "spectra_fem.json")
        result = {"k": k, "fit_options": options, "normalisation": "lambda * area / (4 pi)",
                  "pairs": compare(neural, fem, k),
                  "neural": {r["name"]: normalised(r, k) for r in neural
                             if r["status"] == "done"},
                  "fem": {r["name"]: normalised(r, k) for r in fem}}
        text = json.dumps(result, indent=1) + "\n"

        def write(tmp):
            Path(tmp).write_text(text)

        write_atomically(out / "comparison.json", write)
        for pair, e in result["pairs"].items():
            figures = ", ".join(
                f"{m} mean {e[m]['mean_relative_difference']:.2%} max "
                f"{e[m]['max_relative_difference']:.2%}" for m in ("neural", "fem") if e[m])
            print(f"{pair}: {figures}; neural closer: {e['neural_agrees_more_closely']}")
        try:
            plot(neural, fem, k, out / "spectra.png")
            print(f"wrote {out / 'spectra.png'}")
        except ImportError:
            print("matplotlib not installed: no plot (pip install 'sns-np[plots]')")
        print(f"wrote {out / 'comparison.json'}")
    return 0 if all(r["status"] != "error" for r in fits) else 1


if __name__ == "__main__":
    sys.exit(main())
