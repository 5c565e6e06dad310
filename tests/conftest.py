import os
from pathlib import Path

import numpy as np
import pytest

#: the shared third-party test meshes (never copied into the project)
MESH_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "meshes"
NOJIT = os.environ.get("NUMBA_DISABLE_JIT", "0") == "1"


def _subprocesses_import_this_sns_np():
    """Subprocesses (the CLI, examples, dask workers) import the sns_np these tests import.
    Under ``python -m pytest`` in a checkout that is the checkout, while a subprocess started
    elsewhere would import the installed copy: the same code, but a second Numba cache, so
    every kernel signature was compiled twice in a fresh environment (over a minute in CI)."""
    import sns_np
    root = Path(sns_np.__file__).resolve().parents[1]
    if (root / "pyproject.toml").is_file():          # a checkout, not site-packages
        rest = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        os.environ["PYTHONPATH"] = os.pathsep.join([str(root)] + rest)


_subprocesses_import_this_sns_np()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def mesh_dir():
    if not MESH_DIR.is_dir():
        pytest.skip(f"shared test meshes not found at {MESH_DIR} (present in CI, not in a "
                    "fresh clone)")
    return MESH_DIR


def sphere_points(n, seed=0):
    g = np.random.default_rng(seed)
    p = g.standard_normal((n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def run_cli(argv, capsys):
    """Run the ``sns-np`` command in-process; returns (exit status, stdout, stderr)."""
    from sns_np.cli import main
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:        # argparse: --help, --version and option errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err
