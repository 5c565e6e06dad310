"""Fit a spherical neural surface to a closed genus-0 mesh and save the model.

What it shows: the main pipeline of sns_np in a few lines. The mesh is checked (closed,
manifold, genus 0, outward), mapped bijectively onto the unit sphere (spherical embedding), and
a network S is trained so that S(sphere point) = mesh point, with matching normals. The fitted
surface answers in the mesh's own units and is saved as a .npz model for the other examples.

Run (from the project root):

    python examples/fit_mesh.py                    # the built-in ellipsoid, 2,562 vertices
    python examples/fit_mesh.py ../shared/data/meshes/spot_triangulated.obj
    python examples/fit_mesh.py --help

The default budget is the library's (sns_np.surface.FitOptions; --help shows each default):
a 256 x 8 network, and a time budget chosen from the mesh's detail (docs/fitting.md), as are
the first layer's scale and the learning rate. --time-budget, --steps, --width and --depth trade
accuracy for time.
SNS_NP_SMOKE=1 uses a 32 x 2 network and 50 steps: seconds, and a rough surface.
Output: OUT_DIR/<mesh name>.npz (OUT_DIR defaults to ./sns_np_examples_out).
"""

import argparse
import sys
from pathlib import Path

from _common import (
    BUILTIN,
    DEFAULT_OUT_DIR,
    SMOKE,
    SMOKE_FIT,
    clear_errors,
    output_dir,
    read_mesh,
)

from sns_np.options import add_arguments, given_arguments
from sns_np.surface import FitOptions, fit_mesh

#: the fitting options this example offers (flags, help and defaults come from FitOptions)
FIT_FLAGS = ("steps", "time_budget", "width", "depth", "input_scale", "seed")


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="fit_mesh.py", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mesh", nargs="?", default=None,
                        help="closed genus-0 mesh (.obj, .off, .ply, .stl); "
                             "default: the built-in ellipsoid")
    parser.add_argument("--out-dir", default=DEFAULT_OUT_DIR, help="output folder (%(default)s)")
    add_arguments(parser, FitOptions, FIT_FLAGS)
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    args = parser.parse_args(argv)

    # the library's defaults, unless smoke mode or the command line says otherwise
    budget = dict(SMOKE_FIT) if SMOKE else {}
    budget.update(given_arguments(args, FIT_FLAGS))

    with clear_errors(parser):
        out_dir = output_dir(args.out_dir)
        V, F, name = read_mesh(args.mesh)
        print(f"{args.mesh or 'built-in ellipsoid'}: {len(V)} vertices, {len(F)} triangles")
        # fit_mesh checks the mesh, embeds it on the sphere, then trains; the source is kept
        # in the model so that compare_to_mesh.py can find the mesh again
        source = BUILTIN if args.mesh is None else str(Path(args.mesh).resolve())
        surface, report = fit_mesh(V, F, source=source, progress=not args.quiet, **budget)
        print(report.summary())
        out_dir.mkdir(parents=True, exist_ok=True)
        path = surface.save(out_dir / f"{name}.npz")        # written atomically
        print(f"saved {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
