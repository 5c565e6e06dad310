"""Compare a fitted neural surface with the mesh it was fitted to.

What it shows: how close the smooth surface is to its mesh, and how its exact curvatures
relate to the usual mesh estimates. At every mesh vertex v with sphere point p (the same
spherical embedding the fit used; it is deterministic) we compare

  * position: |S(p) - v|, relative to the diagonal of the mesh's bounding box;
  * normal:   the angle between the network's normal at p and the mesh's vertex normal;
  * curvature: the network's H and K at p against a mesh estimate at v (libigl's quadric fit
    when libigl is installed, else the cotangent / angle-defect formulas).

The mesh estimates are noisy (they depend on the triangulation), so a curvature difference is
not an error of either side alone. For the built-in ellipsoid the exact curvatures are known,
and both are also compared with the truth.

Run (from the project root), after examples/fit_mesh.py:

    python examples/compare_to_mesh.py                    # sns_np_examples_out/ellipsoid.npz
    python examples/compare_to_mesh.py sns_np_examples_out/spot.npz --mesh path/to/spot.obj
    python examples/compare_to_mesh.py --help

Output: a table on the screen and OUT_DIR/<model name>_compare.json.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from _common import BUILTIN, DEFAULT_OUT_DIR, clear_errors, output_dir, read_mesh, write_atomically

from sns_np.geometry import differential_quantities
from sns_np.mesh import (
    baseline_curvatures,
    discrete_curvatures,
    spherical_embedding,
    vertex_normals,
)
from sns_np.surface import SphericalNeuralSurface


def mesh_curvatures(V, F):
    """Mesh H and K: libigl's quadric fit if available, else the discrete formulas."""
    try:
        return baseline_curvatures(V, F), "libigl quadric fit"
    except ImportError:
        return discrete_curvatures(V, F), "cotangent H, angle-defect K"


def relative_difference(a, b):
    """mean |a - b| / mean |b| over points where both are finite."""
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.abs(a[ok] - b[ok]).mean() / np.abs(b[ok]).mean())


def compare(surface, V, F, exact=None):
    Vs, _ = spherical_embedding(V, F, verbose=False)
    dq = differential_quantities(surface, Vs, on_degenerate="nan")
    diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    distance = np.linalg.norm(dq.x - V, axis=1) / diagonal
    cos = np.einsum("ij,ij->i", dq.n, vertex_normals(V, F))
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    curv, method = mesh_curvatures(V, F)
    result = {
        "n_vertices": len(V),
        "position_error_relative_mean": float(distance.mean()),
        "position_error_relative_max": float(distance.max()),
        "normal_angle_deg_mean": float(np.nanmean(angle)),
        "normal_angle_deg_max": float(np.nanmax(angle)),
        "mesh_curvature_method": method,
        "H_neural_vs_mesh": relative_difference(dq.H, curv.H),
        "K_neural_vs_mesh": relative_difference(dq.K, curv.K),
    }
    if exact is not None:
        H_exact, K_exact = exact
        result.update(H_neural_vs_exact=relative_difference(dq.H, H_exact),
                      H_mesh_vs_exact=relative_difference(curv.H, H_exact),
                      K_neural_vs_exact=relative_difference(dq.K, K_exact),
                      K_mesh_vs_exact=relative_difference(curv.K, K_exact))
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="compare_to_mesh.py", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", nargs="?", default=None,
                        help="fitted model (.npz); default: OUT_DIR/ellipsoid.npz, written by "
                             "examples/fit_mesh.py")
    parser.add_argument("--mesh", help="the mesh the model was fitted to; default: the source "
                                       "recorded in the model")
    parser.add_argument("--out-dir", default=DEFAULT_OUT_DIR, help="output folder (%(default)s)")
    args = parser.parse_args(argv)

    with clear_errors(parser):
        out_dir = output_dir(args.out_dir)
        model = Path(args.model) if args.model else out_dir / "ellipsoid.npz"
        if args.model is None and not model.exists():
            raise ValueError(f"no model at {model}; run examples/fit_mesh.py first or name "
                             "a model file")
        surface = SphericalNeuralSurface.load(model)
        source = args.mesh or surface.metadata.get("source")
        if source is None:
            raise ValueError(f"{model} does not record its source mesh; pass --mesh")
        if not args.mesh and source != BUILTIN and not Path(source).is_file():
            raise ValueError(f"{model} was fitted to {source!r}, which is not here; pass --mesh")
        V, F, _ = read_mesh(source)
        if len(V) != surface.metadata.get("n_vertices", len(V)):
            raise ValueError(f"{model} was fitted to a mesh with "
                             f"{surface.metadata['n_vertices']} vertices, {source} has {len(V)}")
        exact = None
        if source == BUILTIN:                    # the vertices lie exactly on the ellipsoid
            from sns_np.demo import ellipsoid_geometry
            _, H_exact, K_exact = ellipsoid_geometry(V, axes=(1.0, 1.3, 0.7))
            exact = (H_exact, K_exact)
        result = {"model": str(model), "mesh": str(source), **compare(surface, V, F, exact)}

        r = result
        print(f"{model} against {source} ({len(V)} vertices)")
        print(f"  position error / bbox diagonal   mean {r['position_error_relative_mean']:.2e}"
              f"   max {r['position_error_relative_max']:.2e}")
        print(f"  normal angle (deg)               mean {r['normal_angle_deg_mean']:.3f}"
              f"   max {r['normal_angle_deg_max']:.2f}")
        print(f"  mean |difference| / mean |mesh value|, mesh by {r['mesh_curvature_method']}:")
        print(f"    H  neural vs mesh  {100 * r['H_neural_vs_mesh']:6.2f}%")
        print(f"    K  neural vs mesh  {100 * r['K_neural_vs_mesh']:6.2f}%")
        if exact is not None:
            print("  against the exact ellipsoid (mean |error| / mean |exact|):")
            for q in "HK":
                print(f"    {q}  neural {100 * r[f'{q}_neural_vs_exact']:6.2f}%"
                      f"   mesh {100 * r[f'{q}_mesh_vs_exact']:6.2f}%")
        path = out_dir / f"{model.stem}_compare.json"
        write_atomically(path, lambda tmp: Path(tmp).write_text(json.dumps(result, indent=2)))
        print(f"saved {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
