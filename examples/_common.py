"""Small helpers shared by the example scripts (not part of the sns_np API).

The scripts import this file as ``_common``; Python finds it because a script's own folder is
first on ``sys.path`` when you run ``python examples/<script>.py``.
"""

from __future__ import annotations

import argparse
import os
from contextlib import contextmanager
from pathlib import Path

#: SNS_NP_SMOKE=1 (set by examples/run_all.py and ``tox -e examples``): tiny budgets, seconds
SMOKE = os.environ.get("SNS_NP_SMOKE", "0") not in ("", "0")
SMOKE_FIT = {"width": 32, "depth": 2, "steps": 50, "batch": 512, "n_eval": 2000}

DEFAULT_OUT_DIR = "sns_np_examples_out"

#: the shared third-party test meshes, beside the project (``../shared/data/meshes``); they
#: are never copied into it, so a fresh clone does not have them
MESH_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "meshes"

#: the default input: an ellipsoid meshed from a level-4 icosphere (2,562 vertices), generated
#: by the package itself, so the examples need no download
BUILTIN = "builtin:ellipsoid(1, 1.3, 0.7):level4"


def read_mesh(path=None):
    """Return ``(V, F, name)`` for a mesh file, or for the built-in ellipsoid when path is None.

    The mesh is read but not checked here: ``fit_mesh`` checks it (closed, manifold, genus 0,
    outward) and raises an error naming the defect.
    """
    if path is None or path == BUILTIN:
        from sns_np.shapes import Ellipsoid
        V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(4)
        return V, F, "ellipsoid"
    from sns_np.mesh import load
    V, F = load(path)
    return V, F, Path(path).stem


def shared_mesh(name) -> Path:
    """The path of one of the shared meshes (e.g. ``spot_triangulated.obj``); a clear
    FileNotFoundError when it is absent."""
    path = MESH_DIR / name
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: the shared meshes live beside the project "
                                f"in ../shared/data/meshes; pass a mesh or a model explicitly")
    return path


def output_dir(path) -> Path:
    """Check the output folder early; it is created when the first file is written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"output folder {str(path)!r} exists and is not a folder")
    return path


def write_atomically(path, write):
    """Call ``write(tmp)`` on a temporary file next to ``path``, then rename it onto ``path``.

    A failure (or Ctrl-C) half-way never leaves a truncated file under the final name. The
    package's own helper does the work: the file gets the permissions of the user's umask and
    is flushed to disk before the rename.
    """
    from sns_np._atomic import write_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_file(path, write)


def positive_int(text):
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {value}")
    return value


@contextmanager
def clear_errors(parser):
    """Turn bad input (ValueError, OSError, missing optional package) into one line, status 2.

    sns_np raises ValueError subclasses that name the problem (the file, the defect found).
    """
    try:
        yield
    except (ValueError, OSError, ImportError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        parser.exit(2, f"{parser.prog}: error: {message}\n")
