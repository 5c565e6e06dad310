"""The ``sns-np`` command.

Each subcommand is a function ``_cmd_<name>(args)``; errors in the input (files, options,
meshes, models) are reported as one line on stderr with exit status 2.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
from pathlib import Path

from ._version import __version__
from .options import given_arguments


class _Parser(argparse.ArgumentParser):
    """argparse with ``--version`` on every (sub)command and one-line errors (status 2)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.add_argument("--version", action="version", version=f"sns-np {__version__}")

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _positive_int(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {v}")
    return v


def _creases(text):
    from .options import check_creases
    try:
        return check_creases(text if text in ("auto", "none") else float(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected auto, none or an angle in degrees in (0, 180], got {text!r}") from None


def _positive_float(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {v}")
    return v


#: the fitting options on the command line (``fit``, ``demo``, ``batch fit``), in help order
FIT_FLAGS = ("steps", "time_budget", "tol", "width", "depth", "batch", "lr", "optimizer",
             "second_moment_decay", "normal_weight", "normal_huber", "area_weight_max",
             "input_scale", "sampling", "vertex_fraction", "dtype", "seed")

def _add_fit_options(p):
    from .options import MESH_SMOOTHING, FitOptions, add_arguments
    g = p.add_argument_group("fitting options (sns_np.surface.FitOptions; docs/fitting.md)")
    add_arguments(g, FitOptions, FIT_FLAGS)
    g.add_argument("--smooth", choices=MESH_SMOOTHING,
                   help=f"position targets: the Phong-tessellated mesh, the surface "
                        f"following the mesh's vertex normals or its flat triangles "
                        f"(default: {MESH_SMOOTHING[0]})")
    g.add_argument("--creases", type=_creases, metavar="{auto,none,DEGREES}",
                   help="keep the two sides of edges sharper than this many degrees apart in "
                        "the target normals; auto (default): 60 on a mesh too coarse for its "
                        "vertex normals to be followed across sharp edges, none otherwise")


def _add_flow_options(p, options):
    """The options heat and mcf share: time, snapshots, sampling, refits, output; ``options``
    is the flow's options dataclass (HeatOptions, MCFOptions)."""
    from .options import DEFAULT_SCHEME, DEFAULT_SNAPSHOTS, SCHEMES, add_arguments
    p.add_argument("--t-end", type=_positive_float, required=True, help="final time")
    p.add_argument("--dt", type=_positive_float, help="time step (default t_end / 100)")
    p.add_argument("--snapshots", type=_positive_int, default=DEFAULT_SNAPSHOTS,
                   help="number of snapshots after t = 0 (%(default)s)")
    add_arguments(p, options, _FLOW_FLAGS, flags={"n_points": "--points"})
    p.add_argument("--level", type=int, default=5, help="icosphere level of the snapshots (5)")
    p.add_argument("--scheme", choices=list(SCHEMES), default=DEFAULT_SCHEME,
                   help="time scheme: heun or midpoint (second order, two refits per step) or "
                        "euler (the paper's first-order step, one refit); the spectral heat "
                        "method is exact in time and ignores it (default: %(default)s)")
    p.add_argument("--force", action="store_true", help="ignore the stability limit")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--output", required=True, help="output folder (must not exist)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


#: the flow options that heat and mcf both put on the command line
_FLOW_FLAGS = ("n_points", "refit_steps")


def _fit_kwargs(args):
    return given_arguments(args, FIT_FLAGS + ("smooth", "creases"))


def build_parser() -> argparse.ArgumentParser:
    from .options import (
        CHECKPOINT_SECONDS,
        CHECKPOINT_STEPS,
        HEAT_METHODS,
        HeatOptions,
        MCFOptions,
        add_arguments,
    )
    parser = _Parser(
        prog="sns-np",
        description="Spherical Neural Surfaces: fit genus-0 meshes with a hand-differentiated "
        "network and compute their differential geometry without meshing.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("demo", help="fit the built-in ellipsoid mesh and report its geometry",
                       description="Fit a neural surface to a generated ellipsoid mesh "
                       "(semi-axes 1, 1.3, 0.7; level-4 icosphere) and compare its normals and "
                       "curvatures with the closed forms.")
    p.add_argument("--level", type=int, default=4, help="icosphere level of the mesh (4)")
    p.add_argument("-o", "--output", help="save the fitted model to this .npz")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_fit_options(p)
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("embed", help="map a genus-0 mesh bijectively onto the unit sphere",
                       description="Check a closed genus-0 mesh and compute a fold-free "
                       "spherical embedding of its vertices; write it as a mesh.")
    p.add_argument("mesh", help="input mesh (.obj, .off, .ply, .stl)")
    p.add_argument("-o", "--output", required=True, help="output mesh (.obj, .ply, ...)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=_cmd_embed)

    p = sub.add_parser("fit", help="fit a neural surface to a mesh",
                       description="Fit a SphericalNeuralSurface to a closed genus-0 mesh and "
                       "save it as .npz. Ctrl-C or SIGTERM stops it between two steps and "
                       "saves a checkpoint; rerun the same command with --resume to continue. "
                       "The checkpoint is also written every --checkpoint-every seconds, so a "
                       "crash loses at most that much work, and is removed once the model is "
                       "saved.")
    p.add_argument("mesh", help="input mesh (.obj, .off, .ply, .stl)")
    p.add_argument("-o", "--output", required=True, help="output model (.npz)")
    p.add_argument("--checkpoint", help="checkpoint file (.npz; default OUTPUT.ckpt.npz)")
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint")
    p.add_argument("--checkpoint-every", type=_positive_float, default=CHECKPOINT_SECONDS,
                   metavar="SECONDS",
                   help=f"write the checkpoint at least this often (default: %(default)g s; "
                        f"also every {CHECKPOINT_STEPS} steps)")
    p.add_argument("--keep-checkpoint", action="store_true",
                   help="keep the checkpoint after a successful fit (default: remove it)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_fit_options(p)
    p.set_defaults(func=_cmd_fit)

    p = sub.add_parser("eval", help="evaluate a model on an icosphere and write a mesh",
                       description="Evaluate a fitted surface at the vertices of an icosphere "
                       "and write the mesh with per-vertex normal, H, K, kmin, kmax, area "
                       "element and principal directions (PLY or VTU keep the fields; OBJ keeps "
                       "geometry only). PLY stores each vector component as its own property "
                       "(normal as nx, ny, nz; dmin as dmin_x, dmin_y, dmin_z); the names "
                       "printed are the names written.")
    p.add_argument("model", help="fitted model (.npz)")
    p.add_argument("-o", "--output", required=True, help="output mesh (.ply, .vtu, .obj)")
    p.add_argument("--level", type=int, default=6,
                   help="icosphere level, 0..8 (10 * 4^level + 2 vertices; 6: 40,962) "
                        "(default: %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("info", help="describe a model file",
                       description="Print a model's architecture, output transform, metadata "
                       "and fit report.")
    p.add_argument("model", help="fitted model (.npz)")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("eigen", help="Laplace-Beltrami eigenmodes of a model",
                       description="Compute the lowest Laplace-Beltrami eigenvalues of a "
                       "fitted surface and write the eigenfunctions as per-vertex fields. "
                       "'ritz' (Rayleigh-Ritz in spherical harmonics of degree <= L) raises L "
                       "until the eigenvalues settle, up to --max-degree; 'neural' trains one "
                       "small network per mode (docs/spectral.md).")
    p.add_argument("model", help="fitted model (.npz)")
    p.add_argument("-k", type=_positive_int, default=10,
                   help="number of non-constant modes (default: %(default)s)")
    p.add_argument("-o", "--output",
                   help="output mesh with the modes (.ply or .vtu) (default: none, print the "
                        "eigenvalues only)")
    p.add_argument("--method", choices=["ritz", "neural"], default="ritz",
                   help="eigensolver (default: %(default)s)")
    p.add_argument("--degree", type=_positive_int, metavar="L",
                   help="ritz: use harmonics of degree <= L, no automatic refinement "
                        "((L+1)^2 basis functions) (default: automatic)")
    p.add_argument("--max-degree", type=_positive_int, default=40, metavar="L_MAX",
                   help="ritz: largest degree the automatic refinement tries; raise it when "
                        "the eigenvalues have not converged (default: %(default)s)")
    p.add_argument("--tol", type=_positive_float, default=1e-6,
                   help="ritz: stop refining when the eigenvalues change by less than this "
                        "(relative) from degree L-2 to L (default: %(default)s)")
    p.add_argument("--steps", type=_positive_int,
                   help="neural: optimisation steps per mode (default: 3000)")
    p.add_argument("--level", type=int, default=5,
                   help="icosphere level of the output mesh, 0..8 (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="random seed of the neural method (default: %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_eigen)

    p = sub.add_parser("heat", help="heat flow of a scalar field on a model",
                       description="Evolve a scalar field on a fitted surface by the heat "
                       "equation f_t = Delta f and write PLY snapshots (field 'f' per vertex) "
                       "into a new output folder, written atomically.")
    p.add_argument("model", help="fitted model (.npz)")
    p.add_argument("--field", required=True,
                   help="initial field: 'sh:L,M' (spherical harmonic of the sphere point), "
                        "'x', 'y' or 'z' (a coordinate of the surface) or a NeuralField .npz")
    p.add_argument("--method", choices=HEAT_METHODS, default=HEAT_METHODS[0],
                   help="explicit steps of a network, or exact in time through eigenmodes "
                        "(default: %(default)s)")
    add_arguments(p, HeatOptions, ("k",), flags={"k": "-k"})
    _add_flow_options(p, HeatOptions)
    p.set_defaults(func=_cmd_heat)

    p = sub.add_parser("mcf", help="mean curvature flow of a model",
                       description="Evolve a fitted surface by mean curvature flow "
                       "X_t = -2 H n and write PLY snapshots (normal, H, K per vertex) and the "
                       "snapshot models into a new output folder, written atomically.")
    p.add_argument("model", help="fitted model (.npz)")
    add_arguments(p, MCFOptions, ("lr",))
    _add_flow_options(p, MCFOptions)
    p.set_defaults(func=_cmd_mcf)

    p = sub.add_parser("batch", help="fit many meshes, or their spectra, on a Dask cluster",
                       description="Collections of shapes on dask.distributed: a local "
                       "cluster of processes sized to the machine, or a running scheduler "
                       "(--scheduler). Needs the extra: pip install \"sns-np[distributed]\" "
                       "(docs/batch.md).")
    bsub = p.add_subparsers(dest="batch_command", metavar="BATCH_COMMAND", required=True)
    b = bsub.add_parser("fit", help="fit every mesh: DIR/NAME.npz and DIR/summary.csv, .json",
                        description="Fit a neural surface to every mesh, one Dask task per "
                        "mesh, and write DIR/NAME.npz per mesh with DIR/summary.csv and "
                        "DIR/summary.json (one row per mesh: status, time, fit figures, "
                        "output). A bad mesh fails its own row. Each fit checkpoints to "
                        "NAME.ckpt.npz and a rescheduled task resumes from it; rerunning the "
                        "command skips complete outputs. Exit status 1 when a row failed.")
    b.add_argument("meshes", nargs="+", metavar="MESH",
                   help="input meshes (.obj, .off, .ply, .stl); their names must differ")
    b.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder")
    _add_cluster_options(b)
    b.add_argument("--checkpoint", metavar="FOLDER",
                   help="folder of the checkpoints NAME.ckpt.npz (default: DIR)")
    b.add_argument("--resume", action="store_true",
                   help="accepted for symmetry with 'sns-np fit': a batch always resumes "
                        "from the checkpoints it finds")
    b.add_argument("--checkpoint-every", type=_positive_float, default=CHECKPOINT_SECONDS,
                   metavar="SECONDS",
                   help="write each fit's checkpoint at least this often (default: %(default)g"
                        " s): a killed worker loses at most that much of its fit")
    b.add_argument("--keep-checkpoint", action="store_true",
                   help="keep the checkpoints after the models are saved")
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_fit_options(b)
    b.set_defaults(func=_cmd_batch_fit, command="batch fit")
    b = bsub.add_parser("spectrum", help="first k Laplace-Beltrami eigenvalues of every model",
                        description="Compute the first K non-zero Laplace-Beltrami eigenvalues "
                        "of every model by Rayleigh-Ritz (as 'sns-np eigen'), one Dask task "
                        "per model, and write them as a table (CSV, and JSON beside it). "
                        "Exit status 1 when a row failed.")
    b.add_argument("models", nargs="+", metavar="MODEL", help="fitted models (.npz)")
    b.add_argument("-k", type=_positive_int, required=True, help="eigenvalues per model")
    b.add_argument("-o", "--output", required=True, metavar="TABLE.csv",
                   help="output table (.csv; the .json goes beside it)")
    b.add_argument("--max-degree", type=_positive_int, default=40, metavar="L_MAX",
                   help="largest harmonic degree tried (default: %(default)s)")
    b.add_argument("--tol", type=_positive_float, default=1e-6,
                   help="relative change of the eigenvalues at which the degree stops rising "
                        "(default: %(default)s)")
    _add_cluster_options(b)
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=_cmd_batch_spectrum, command="batch spectrum")
    return parser


def _add_cluster_options(p):
    g = p.add_argument_group("cluster (default: a local cluster of processes, one per core)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="address of a running Dask scheduler, e.g. tcp://host:8786")
    g.add_argument("--workers", type=_positive_int, metavar="N",
                   help="worker processes of the local cluster (default: one per core; "
                        "processes x threads = cores)")
    g.add_argument("--threads-per-fit", type=_positive_int, default=1, metavar="N",
                   help="BLAS and Numba threads of each task (default: %(default)s); models "
                        "are bit-identical across workers at a fixed value")


# ------------------------------------------------------------------------------ commands

def _load_model(path):
    from .surface import SphericalNeuralSurface
    return SphericalNeuralSurface.load(path)


def _check_output(path, suffixes):
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValueError(f"output {path.name!r} must end in one of {', '.join(suffixes)}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"output folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"output folder {str(folder)!r} is not writable")
    return path


def _check_level(level, hi=8):
    if not 0 <= level <= hi:
        raise ValueError(f"--level must be between 0 and {hi}, got {level}")


def _cmd_demo(args):
    from .demo import run_demo
    _check_level(args.level)
    if args.output:
        _check_output(args.output, (".npz",))
    run_demo(level=args.level, out=args.output, progress=not args.quiet, **_fit_kwargs(args))
    return 0


def _cmd_embed(args):
    from .mesh import check, load, spherical_embedding, write_mesh
    out = _check_output(args.output, (".obj", ".ply", ".off", ".vtu", ".stl"))
    V, F = load(args.mesh)
    check(V, F)
    Vs, report = spherical_embedding(V, F, verbose=not args.quiet)
    write_mesh(out, Vs, F)
    print(f"{args.mesh}: {len(V)} vertices embedded on the sphere; {report}")
    print(f"wrote {out}")
    return 0


def _cmd_fit(args):
    from ._atomic import exclusive, remove_stale_temporaries
    from .errors import FitInterrupted
    from .mesh import load
    from .surface import fit_mesh
    # names checked now, not at the first write many minutes into the fit
    out = _check_output(args.output, (".npz",))
    ckpt = (_check_output(args.checkpoint, (".npz",)) if args.checkpoint
            else out.with_suffix(".ckpt.npz"))
    if args.resume and not ckpt.exists():
        raise ValueError(f"--resume: no checkpoint at {ckpt}")
    with exclusive(out):                          # a second fit to the same output is refused
        for tmp in remove_stale_temporaries(out):
            print(f"removed {tmp}, left by an interrupted run", file=sys.stderr)
        V, F = load(args.mesh)
        try:
            surface, report = fit_mesh(
                V, F, checkpoint=ckpt, resume=args.resume, checkpoint_seconds=args.checkpoint_every,
                progress=not args.quiet, source=str(Path(args.mesh).resolve()),
                **_fit_kwargs(args))
        except FitInterrupted as exc:
            if exc.checkpoint is None:
                raise
            raise _Interrupted(f"interrupted by {exc.signal_name} after step {exc.step}; the "
                               f"checkpoint {exc.checkpoint} holds it: rerun the same command "
                               f"with --resume to continue", exc.signal_name) from None
        surface.save(out)
        if not args.keep_checkpoint:
            ckpt.unlink(missing_ok=True)
    for line in _choice_lines(report.choices):
        print(line)
    print(report.summary())
    print(f"wrote {out}" + (f" (checkpoint kept: {ckpt})" if args.keep_checkpoint else ""))
    return 0


def _cmd_batch_fit(args):
    from .batch import fit_many
    if args.scheduler and args.workers:
        raise ValueError("--workers applies to a local cluster; a running scheduler "
                         "(--scheduler) has its own workers")
    table = fit_many(args.meshes, args.output, scheduler=args.scheduler, workers=args.workers,
                     threads_per_fit=args.threads_per_fit, checkpoint_dir=args.checkpoint,
                     checkpoint_seconds=args.checkpoint_every,
                     keep_checkpoint=args.keep_checkpoint, progress=not args.quiet,
                     **_fit_kwargs(args))
    print(_printable(table.format(["name", "status", "steps", "position_relative",
                                   "normal_mean_deg", "seconds", "message"])))
    out = Path(args.output)
    return _batch_status(table, f"{out / 'summary.csv'} and {out / 'summary.json'}")


def _cmd_batch_spectrum(args):
    from .batch import spectra_many
    if args.scheduler and args.workers:
        raise ValueError("--workers applies to a local cluster; a running scheduler "
                         "(--scheduler) has its own workers")
    table = spectra_many(args.models, args.k, scheduler=args.scheduler, workers=args.workers,
                         out=args.output, threads_per_fit=args.threads_per_fit,
                         progress=False if args.quiet else True, L_max=args.max_degree,
                         tol=args.tol)
    shown = ["name", "status", "L"] + [f"lambda_{i}" for i in range(1, min(args.k, 5) + 1)]
    print(_printable(table.format(shown + ["message"])))
    out = Path(args.output)
    return _batch_status(table, f"{out} and {out.with_suffix('.json')}")


def _batch_status(table, written):
    """Exit status of a batch: 0 when every row is done or skipped, 1 when a row failed."""
    failed = [r["name"] for r in table if r["status"] == "error"]
    print(f"wrote {written}")
    if failed:
        print(f"sns-np batch: {len(failed)} of {len(table)} failed ({', '.join(failed[:5])}"
              f"{', ...' if len(failed) > 5 else ''}); their rows say why", file=sys.stderr)
        return 1
    return 0


class _Interrupted(KeyboardInterrupt):
    """An interrupt with the message the user should see and the signal's name."""

    def __init__(self, message, signal_name="SIGINT"):
        super().__init__(message)
        self.signal_name = signal_name


def _raise_on_sigterm(signum, frame):
    raise _Interrupted("terminated (SIGTERM)", "SIGTERM")


def _choice_lines(choices):
    """One line per option that the fit chose by itself, with the reason."""
    out = []
    for k, c in (choices or {}).items():
        if isinstance(c, dict):
            v = c.get("value")
            v = f"{v:.3g}" if isinstance(v, float) else v
            verb = "measured" if k in ("detail", "normal_detail") else "chosen"
            out.append(f"  {verb} {_printable(k)} = {_printable(v)} "
                       f"({_printable(c.get('why'))})")
    return out


def _cmd_eval(args):
    from .mesh import write_mesh, written_field_names
    out = _check_output(args.output, (".ply", ".vtu", ".obj"))
    _check_level(args.level)
    S = _load_model(args.model)
    fields = out.suffix.lower() != ".obj"
    V, F, data = S.to_mesh(args.level, fields=fields, progress=not args.quiet)
    data.pop("sphere", None)
    write_mesh(out, V, F, data if fields else None)
    names = written_field_names(out, data) if fields else []
    print(f"wrote {out}: {len(V)} vertices" + (f", fields {', '.join(names)}" if names else ""))
    return 0


def _cmd_info(args):
    import json
    S = _load_model(args.model)
    net = S.net
    print(f"model: {args.model}")
    print(f"  network: width {net.width}, depth {net.depth}, bias {net.bias}, "
          f"{net.n_params:,} parameters")
    print(f"  output transform: centre {S.center.round(6).tolist()}, scale {S.scale:.6g}")
    meta = dict(S.metadata)
    fit = meta.pop("fit", None)
    for k, v in meta.items():
        print(f"  {_printable(k)}: {_printable(v)}")
    if fit:
        print(f"  fit: {fit.get('steps')} steps, {fit.get('seconds', 0):.1f} s, stopped by "
              f"{_printable(fit.get('stopped'))}; held-out position error "
              f"{fit.get('position_mean'):.3g} "
              f"(relative {fit.get('position_relative'):.2e}), normal error "
              f"{fit.get('normal_mean_deg'):.3f} deg")
        dist, nrm = fit.get("distance_relative"), fit.get("closest_normal_mean_deg")
        if isinstance(dist, float) and math.isfinite(dist) and isinstance(nrm, float):
            vd, diag = fit.get("vertex_distance_mean"), fit.get("bbox_diagonal")
            back = (f" (its vertices to the surface {vd / diag:.2e})"
                    if isinstance(vd, float) and math.isfinite(vd) and isinstance(diag, float)
                    and diag > 0 else "")
            print(f"  against the mesh: distance {dist:.2e} of the bbox diagonal{back}, normal "
                  f"error {nrm:.3f} deg at the nearest point")
        closing = fit.get("closing_readout")
        if isinstance(closing, dict) and closing:
            try:
                t = [round(float(x), 9) for x in closing["translation"]]
                print(f"  closing read-out (the position term's least squares): translation "
                      f"{t}, read-out change {float(closing['readout_change']):.3g}")
            except (TypeError, ValueError, KeyError):
                print(f"  closing read-out: {_printable(closing)}")
        opts = fit.get("options", {})
        if opts:
            print(f"  fit options: {_printable(json.dumps(opts))}")
        for line in _choice_lines(fit.get("choices")):
            print(" " + line)
        notes = fit.get("notes")
        for n in notes if isinstance(notes, list) else []:
            print(f"  note: {_printable(n)}")
    return 0


def _printable(value):
    """str(value) with control and other non-printable characters escaped (metadata comes
    from a file: a terminal escape sequence must not reach the terminal)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(value))


def _cmd_eigen(args):
    import warnings

    from .mesh import write_mesh, written_field_names
    from .spectral import eigenmodes, eigenmodes_on_mesh
    out = _check_output(args.output, (".ply", ".vtu")) if args.output else None
    _check_level(args.level)   # before the eigenmodes, not after
    if args.method == "ritz":
        if args.steps is not None:
            raise ValueError("--steps applies to --method neural only")
        opts = {"L": args.degree, "L_max": args.max_degree, "tol": args.tol}
    else:
        if args.degree is not None:
            raise ValueError("--degree applies to --method ritz only")
        opts = {} if args.steps is None else {"steps": args.steps}
    S = _load_model(args.model)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            res = eigenmodes(S, args.k, method=args.method, rng=args.seed,
                             progress=not args.quiet, **opts)
        except ValueError as exc:   # "k modes need degree ... > L_max": name the options
            raise ValueError(_cli_terms(str(exc))) from None
    for w in caught:
        print(f"sns-np eigen: warning: {_cli_terms(str(w.message))}", file=sys.stderr)
    for i, lam in enumerate(res.eigenvalues, start=1):
        print(f"lambda_{i} = {lam:.6g}")
    if out is not None:
        V, F, data = eigenmodes_on_mesh(res, S, args.level)
        write_mesh(out, V, F, data)
        print(f"wrote {out}: {len(V)} vertices, fields "
              f"{', '.join(written_field_names(out, data))}")
    return 0


def _cli_terms(message):
    """A library message with its keyword names replaced by the options of ``sns-np eigen``."""
    return (message.replace("raise L_max or pass a larger L",
                            "raise --max-degree or pass a larger --degree")
            .replace("raise L_max", "raise --max-degree")
            .replace("raise L or leave it None (automatic)",
                     "raise --degree or leave it out (automatic)"))


def _check_output_folder(path, level):
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"parent folder {str(parent)!r} of the output does not exist")
    if path.exists() and (not path.is_dir() or any(path.iterdir())):
        raise ValueError(f"output {str(path)!r} already exists; remove it or choose another")
    if not 0 <= level <= 8:
        raise ValueError(f"--level must be between 0 and 8, got {level}")
    return path


def _parse_field(spec, surface):
    from .fields import NeuralField
    from .shapes import ComponentField, SphericalHarmonic
    spec = spec.strip()
    if spec in ("x", "y", "z"):
        return ComponentField(surface, "xyz".index(spec))
    if spec.startswith("sh:"):
        try:
            l, m = (int(v) for v in spec[3:].split(","))
        except ValueError:
            raise ValueError(f"--field {spec!r}: expected 'sh:L,M' with integers, e.g. "
                             f"sh:2,1") from None
        return SphericalHarmonic(l, m)
    if spec.endswith(".npz"):
        return NeuralField.load(spec)
    raise ValueError(f"--field {spec!r}: expected 'sh:L,M', 'x', 'y', 'z' or a NeuralField "
                     f".npz")


def _run_flow(run, save, out, label):
    """Run a flow; on divergence keep the snapshots up to the last good one, then fail."""
    from .errors import DivergenceError
    try:
        res = run()
    except DivergenceError as exc:
        partial = getattr(exc, "result", None)
        if partial is not None and len(partial):
            save(partial)
            raise DivergenceError(f"{exc} (wrote {len(partial)} snapshots up to t = "
                                  f"{partial.times[-1]:.6g} to {out})") from None
        raise
    save(res)
    refits = res.info.get("refits")
    cost = f" ({refits} refits, scheme {res.info['scheme']})" if refits else ""
    print(f"{label}: {len(res)} snapshots t = 0 .. {res.times[-1]:.6g} in {res.steps} steps"
          f"{cost}, {res.seconds:.1f} s; wrote {out}")
    return res


def _cmd_heat(args):
    from .flows import heat_flow
    out = _check_output_folder(args.output, args.level)
    S = _load_model(args.model)
    field = _parse_field(args.field, S)
    dt = args.dt or args.t_end / 100
    opts = given_arguments(args, _FLOW_FLAGS if args.method == "network" else ("k",))
    _run_flow(lambda: heat_flow(S, field, args.t_end, dt, method=args.method,
                                scheme=args.scheme, n_snapshots=args.snapshots,
                                stability="ignore" if args.force else "raise", rng=args.seed,
                                progress=not args.quiet, **opts),
              lambda res: res.save(out, S, level=args.level), out, f"heat ({args.method})")
    return 0


def _cmd_mcf(args):
    from .flows import mean_curvature_flow
    out = _check_output_folder(args.output, args.level)
    S = _load_model(args.model)
    dt = args.dt or args.t_end / 100
    opts = given_arguments(args, _FLOW_FLAGS + ("lr",))
    res = _run_flow(lambda: mean_curvature_flow(
        S, args.t_end, dt, scheme=args.scheme, n_snapshots=args.snapshots,
        stability="ignore" if args.force else "raise", rng=args.seed,
        progress=not args.quiet, **opts), lambda res: res.save(out, level=args.level), out,
        "mcf")
    print("areas: " + ", ".join(f"{a:.6g}" for a in res.areas))
    return 0


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "command", None) is None:
        parser.print_help()
        return 0
    # SIGTERM unwinds like Ctrl-C, so that partial outputs are cleaned up and a fit saves
    # its checkpoint (the main thread only: signal handlers cannot be set elsewhere)
    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _raise_on_sigterm)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:
        name = getattr(exc, "signal_name", "SIGINT")
        message = str(exc) if isinstance(exc, _Interrupted) else "interrupted"
        print(f"sns-np {args.command}: {message}", file=sys.stderr)
        return 143 if name == "SIGTERM" else 130
    except (ValueError, OSError, ImportError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"sns-np {args.command}: error: {msg}", file=sys.stderr)
        return 2
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
