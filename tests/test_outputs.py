"""Outputs (issue 13): permissions, durability and atomicity of every file the package writes,
and what ``sns-np eval`` and ``sns-np eigen`` print and offer."""

import argparse
import os
import sys

import numpy as np
import pytest

from sns_np import _atomic
from sns_np.cli import build_parser, main
from sns_np.mesh import icosphere, write_mesh, written_field_names
from sns_np.nn import ResidualMLP
from sns_np.surface import SphericalNeuralSurface

from .conftest import run_cli

posix_only = pytest.mark.skipif(sys.platform == "win32", reason="POSIX permission bits")


run = run_cli


@pytest.fixture
def umask():
    """Set a umask for one test and restore the previous one."""
    old = os.umask(0o022)
    yield lambda mask: os.umask(mask)
    os.umask(old)


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("outputs") / "model.npz"
    SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0).save(path)
    return path


def _write_everything(folder):
    """One file of each writer: a model, a network, a mesh, a flow folder."""
    from sns_np.flows._common import atomic_folder
    P, T = icosphere(1)
    S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0))
    S.save(folder / "model.npz")
    S.net.save(folder / "net.npz")
    write_mesh(folder / "mesh.ply", P, T, {"h": P[:, 2]})
    write_mesh(folder / "mesh.obj", P, T)
    atomic_folder(folder / "flow", lambda tmp: (tmp / "a.json").write_text("{}"))
    return ["model.npz", "net.npz", "mesh.ply", "mesh.obj", "flow/a.json"]


@posix_only
@pytest.mark.parametrize("mask, file_mode, dir_mode", [(0o022, 0o644, 0o755),
                                                       (0o077, 0o600, 0o700),
                                                       (0o002, 0o664, 0o775)])
def test_files_get_the_umask_permissions_not_0600(mask, file_mode, dir_mode, umask, tmp_path):
    umask(mask)
    names = _write_everything(tmp_path)
    for name in names:
        assert (tmp_path / name).stat().st_mode & 0o777 == file_mode, name
    assert (tmp_path / "flow").stat().st_mode & 0o777 == dir_mode
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["model.npz", "net.npz", "mesh.ply", "mesh.obj", "flow"])   # no temporaries left


def test_data_is_fsynced_before_the_rename(tmp_path, monkeypatch):
    events = []
    real_fsync, real_replace, real_rename = os.fsync, os.replace, os.rename

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")
                       if os.path.exists(f"/proc/self/fd/{fd}") else fd))
        return real_fsync(fd)

    def replace(a, b):
        events.append(("replace", str(a), str(b)))
        return real_replace(a, b)

    def rename(a, b):
        events.append(("rename", str(a), str(b)))
        return real_rename(a, b)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(os, "rename", rename)
    SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0)).save(tmp_path / "m.npz")
    kinds = [e[0] for e in events]
    assert kinds.count("replace") == 1
    i = kinds.index("replace")
    tmp = events[i][1]
    assert events[i][2] == str(tmp_path / "m.npz") and tmp.endswith(".tmp")
    assert "fsync" in kinds[:i]                     # the data before the rename
    assert "fsync" in kinds[i + 1:]                 # the folder entry after it
    if sys.platform.startswith("linux"):
        assert events[kinds.index("fsync")][1] == tmp

    events.clear()
    from sns_np.flows._common import atomic_folder
    atomic_folder(tmp_path / "out", lambda d: (d / "f.txt").write_text("x"))
    kinds = [e[0] for e in events]
    i = kinds.index("rename")
    assert kinds[:i].count("fsync") >= 2            # the file and its folder, before


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")

    def write(tmp):
        tmp.write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _atomic.write_file(target, write)
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
    with pytest.raises(OSError, match="does not exist"):
        _atomic.write_file(tmp_path / "missing" / "x.txt", lambda tmp: None)


def test_stale_temporaries_are_listed(tmp_path):
    target = tmp_path / "model[1].npz"
    left = tmp_path / "model[1].npz.0badc0de.tmp"
    left.write_bytes(b"")
    (tmp_path / "other.npz.0badc0de.tmp").write_bytes(b"")
    assert _atomic.stale_temporaries(target) == [left]


def test_no_writer_uses_mkstemp_or_its_own_rename():
    """One helper: every atomic write in the package goes through sns_np/_atomic.py."""
    import sns_np
    root = os.path.dirname(sns_np.__file__)
    offenders = []
    for folder, _, files in os.walk(root):
        for name in files:
            if name.endswith(".py") and name != "_atomic.py":
                with open(os.path.join(folder, name), encoding="utf-8") as fh:
                    code = [line for line in fh if ">>>" not in line]   # not the doctests
                for needle in ("mkstemp", "mkdtemp", "os.replace("):
                    if any(needle in line for line in code):
                        offenders.append(f"{name}: {needle}")
    assert offenders == []


# ------------------------------------------------------------------------------ sns-np eval

def _ply_properties(path):
    names = []
    with open(path, "rb") as fh:
        for line in fh:
            line = line.decode("ascii").strip()
            if line == "end_header":
                break
            if line.startswith("property ") and not line.startswith("property list"):
                names.append(line.split()[-1])
    return [n for n in names if n not in ("x", "y", "z")]


@pytest.mark.parametrize("suffix", [".ply", ".vtu"])
def test_eval_prints_the_field_names_it_writes(suffix, model, tmp_path, capsys):
    out_path = tmp_path / f"surface{suffix}"
    code, out, err = run(["eval", model, "-o", out_path, "--level", 1, "--quiet"], capsys)
    assert code == 0 and err == ""
    printed = out.split("fields ", 1)[1].strip().split(", ")
    if suffix == ".ply":
        written = _ply_properties(out_path)
        assert written[:3] == ["nx", "ny", "nz"] and "dmin_x" in written
    else:
        import meshio
        written = list(meshio.read(out_path).point_data)
        assert "normal" in written
    assert printed == written


def test_written_field_names_follow_write_mesh(tmp_path):
    P, T = icosphere(0)
    fields = {"normal": P, "v": P[:, :2], "s": P[:, 0], "w": np.zeros((len(P), 4))}
    write_mesh(tmp_path / "a.ply", P, T, fields)
    assert written_field_names(tmp_path / "a.ply", fields) == _ply_properties(tmp_path / "a.ply")
    assert written_field_names("a.obj", fields) == []


def test_eval_and_eigen_show_progress_unless_quiet(model, tmp_path, capsys):
    code, _, err = run(["eval", model, "-o", tmp_path / "s.ply", "--level", 1], capsys)
    assert code == 0 and "eval 42/42" in err
    code, _, err = run(["eigen", model, "-k", 2], capsys)
    assert code == 0 and "ritz" in err and "L " in err
    code, _, err = run(["eigen", model, "-k", 2, "--quiet"], capsys)
    assert code == 0 and err == ""


# ------------------------------------------------------------------------------ sns-np eigen

def test_eigen_exposes_the_basis_size(model, capsys):
    code, out, err = run(["eigen", model, "-k", 3, "--degree", 3, "--quiet"], capsys)
    assert code == 0 and err == "" and out.count("lambda_") == 3
    # too small a basis: the message names the option to raise, not a keyword argument
    code, out, err = run(["eigen", model, "-k", 30, "--degree", 2, "--quiet"], capsys)
    assert code == 2 and "--degree" in err and "L =" not in err.replace("L = 2", "")
    code, out, err = run(["eigen", model, "-k", 30, "--max-degree", 5, "--quiet"], capsys)
    assert code == 2 and "raise --max-degree" in err and "L_max" not in err.split("=")[-1]
    # not converged at the largest degree: a warning that names --max-degree
    code, out, err = run(["eigen", model, "-k", 3, "--max-degree", 6, "--tol", 1e-15,
                          "--quiet"], capsys)
    assert code == 0 and out.count("lambda_") == 3
    assert "warning" in err and "raise --max-degree or pass a larger --degree" in err
    code, _, err = run(["eigen", model, "--method", "neural", "--degree", 3], capsys)
    assert code == 2 and "--degree applies to --method ritz only" in err


def _subparser(name):
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[name]


@pytest.mark.parametrize("command", ["eval", "eigen", "info"])
def test_every_option_has_help_and_shows_its_default(command, capsys):
    p = _subparser(command)
    assert p.description
    for action in p._actions:
        assert action.help, f"{command} {action.dest} has no help"
        if action.option_strings and action.default not in (None, False, argparse.SUPPRESS):
            assert "(default: %(default)s)" in action.help, f"{command} {action.dest}"
        elif action.option_strings and action.nargs != 0 and action.default is None:
            assert "default" in action.help or action.required, f"{command} {action.dest}"
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    if command == "eigen":
        assert "--max-degree L_MAX" in text and "(default: 40)" in text


# ------------------------------------------------------------------------------ examples

def test_curvature_map_example_runs_with_no_argument(tmp_path):
    """The README promises it: no model named and none fitted yet, it fits a small built-in
    surface by itself (smoke budget here; the default run takes seconds)."""
    import subprocess
    from pathlib import Path
    pytest.importorskip("matplotlib")
    script = Path(__file__).resolve().parents[1] / "examples" / "curvature_map.py"
    if not script.is_file():
        pytest.skip("examples/ not present")
    env = dict(os.environ, SNS_NP_SMOKE="1", MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "sns_np_examples_out"
    assert (out / "ellipsoid_small.npz").is_file()
    assert (out / "ellipsoid_small_curvature.png").stat().st_size > 10_000
    assert "fitting a small network" in proc.stdout
