"""The ``sns-np`` command: help and version, each subcommand on tiny inputs, and bad input.

Commands run in-process through ``sns_np.cli.main`` (fast); one test runs ``python -m sns_np``
in a subprocess to check the real exit status. Every failure must exit with status 2, print one
line on stderr naming the problem, and leave no file behind.
"""

import subprocess
import sys

import numpy as np
import pytest

from sns_np import __version__
from sns_np.mesh import icosphere, load, orientation_determinants, write_mesh
from sns_np.nn import ResidualMLP
from sns_np.shapes import Ellipsoid
from sns_np.surface import SphericalNeuralSurface

from .conftest import run_cli

COMMANDS = ["demo", "embed", "fit", "eval", "info", "eigen", "batch"]
TINY_FIT = ["--steps", "5", "--width", "16", "--depth", "1", "--quiet"]


run = run_cli


# ------------------------------------------------------------------------------ fixtures

@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A small model, a small closed mesh and a handful of broken inputs, in one folder."""
    d = tmp_path_factory.mktemp("cli_inputs")
    model = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0),
                                   center=[0.5, 0.0, -1.0], scale=2.0,
                                   metadata={"source": "test_cli"})
    model.save(d / "model.npz")
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)                  # 162 vertices
    write_mesh(d / "ellipsoid.obj", V, F)

    P, T = icosphere(1)
    write_mesh(d / "open.obj", P, T[1:])                     # one face missing
    write_mesh(d / "inward.obj", P, T[:, ::-1])
    write_mesh(d / "torus.obj", *_torus())
    write_mesh(d / "pinched.obj", *_two_spheres_sharing_a_vertex(P, T))
    text = (d / "ellipsoid.obj").read_text().splitlines()
    i = next(k for k, line in enumerate(text) if line.startswith("v "))
    text[i] = "v nan 0 0"
    (d / "nan.obj").write_text("\n".join(text) + "\n")
    (d / "mesh.xyz").write_text("0 0 0\n")
    (d / "garbage.npz").write_bytes(b"this is not a zip archive")
    raw = (d / "model.npz").read_bytes()
    (d / "truncated.npz").write_bytes(raw[: len(raw) // 2])
    np.savez(d / "not_a_model.npz", a=np.zeros(3))
    state = model.state()
    state["format_version"] = np.array(99)
    np.savez(d / "future.npz", **state)
    return d


def _torus(n=12, m=8):
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    a, b = 2 * np.pi * i.ravel() / n, 2 * np.pi * j.ravel() / m
    V = np.stack([(2 + np.cos(b)) * np.cos(a), (2 + np.cos(b)) * np.sin(a), np.sin(b)], axis=1)
    idx = lambda i, j: (i % n) * m + (j % m)
    F = [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)] for i in range(n) for j in range(m)]
    F += [[idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)] for i in range(n) for j in range(m)]
    return V, np.array(F)


def _two_spheres_sharing_a_vertex(P, T):
    """Two unit spheres touching at one vertex: closed, but not vertex-manifold."""
    Q = P + [2.0, 0.0, 0.0]
    a, b = int(np.argmax(P[:, 0])), int(np.argmin(Q[:, 0]))
    Q = np.delete(Q, b, axis=0)
    T2 = T + len(P)
    T2[T == b] = a
    T2[T > b] -= 1
    return np.vstack([P, Q]), np.vstack([T, T2])


# ------------------------------------------------------------------------------ help, version

def test_version(capsys):
    code, out, _ = run(["--version"], capsys)
    assert code == 0 and out.strip() == f"sns-np {__version__}"


@pytest.mark.parametrize("command", COMMANDS)
def test_subcommand_help_and_version(command, capsys):
    code, out, _ = run([command, "--help"], capsys)
    assert code == 0
    assert out.startswith(f"usage: sns-np {command}")
    code, out, _ = run([command, "--version"], capsys)
    assert code == 0 and out.strip() == f"sns-np {__version__}"


def test_program_help_lists_every_command(capsys):
    code, out, _ = run(["--help"], capsys)
    assert code == 0
    assert all(c in out for c in COMMANDS)
    code, out2, _ = run([], capsys)                          # no command: the same help
    assert code == 0 and out2 == out


def test_python_m_sns_np(files):
    """The real process: version on stdout; an error is one line on stderr, status 2."""
    ok = subprocess.run([sys.executable, "-m", "sns_np", "--version"],
                        capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0 and ok.stdout.strip() == f"sns-np {__version__}"
    bad = subprocess.run([sys.executable, "-m", "sns_np", "info", str(files / "nope.npz")],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stdout == ""
    assert bad.stderr.splitlines() == [f"sns-np info: error: model file "
                                       f"{str(files / 'nope.npz')!r} does not exist"]


# ------------------------------------------------------------------------------ subcommands

def test_info(files, capsys):
    code, out, err = run(["info", files / "model.npz"], capsys)
    assert code == 0 and err == ""
    n_params = ResidualMLP(width=8, depth=1).n_params
    assert f"width 8, depth 1, bias False, {n_params:,} parameters" in out
    assert "centre [0.5, 0.0, -1.0], scale 2" in out
    assert "source: test_cli" in out


def test_info_prints_an_analytic_fits_closing_readout(tmp_path, capsys):
    from sns_np.surface import fit_shape
    S, r = fit_shape(Ellipsoid(1.0, 1.3, 0.7), width=8, depth=1, steps=5, batch=64,
                     n_eval=100, progress=False)
    S.save(tmp_path / "e.npz")
    code, out, _ = run(["info", tmp_path / "e.npz"], capsys)
    t, change = r.closing_readout["translation"], r.closing_readout["readout_change"]
    assert code == 0 and len(t) == 3 and 0 <= change
    assert (f"closing read-out (the position term's least squares): translation "
            f"{[round(x, 9) for x in t]}, read-out change {change:.3g}") in out
    assert (f"closing read-out: translation {np.linalg.norm(t):.3g}, read-out change "
            f"{change:.3g}") in r.summary()


def test_eval_writes_fields_in_the_model_units(files, tmp_path, capsys):
    import meshio
    out_path = tmp_path / "surface.ply"
    code, out, err = run(["eval", files / "model.npz", "-o", out_path, "--level", 2, "--quiet"],
                         capsys)
    assert code == 0 and err == ""                           # no meshio warnings either
    assert f"wrote {out_path}: 162 vertices" in out
    mesh = meshio.read(out_path)
    S = SphericalNeuralSurface.load(files / "model.npz")
    V, F, data = S.to_mesh(2)
    assert np.allclose(mesh.points, V) and np.array_equal(mesh.cells[0].data, F)
    for name in ("H", "K", "kmin", "kmax", "area_element", "nx"):
        assert name in mesh.point_data
    assert np.allclose(mesh.point_data["H"], data["H"], equal_nan=True)
    assert np.allclose(mesh.point_data["nz"], data["normal"][:, 2], equal_nan=True)


def test_eval_obj_keeps_geometry_only(files, tmp_path, capsys):
    out_path = tmp_path / "surface.obj"
    code, out, _ = run(["eval", files / "model.npz", "-o", out_path, "--level", 1], capsys)
    assert code == 0 and "fields" not in out
    V, F = load(out_path)
    assert V.shape == (42, 3) and F.shape == (80, 3)


def test_embed_is_fold_free_on_the_unit_sphere(files, tmp_path, capsys):
    out_path = tmp_path / "sphere.obj"
    code, out, err = run(["embed", files / "ellipsoid.obj", "-o", out_path, "--quiet"], capsys)
    assert code == 0 and err == ""
    assert "162 vertices embedded" in out
    Vs, F = load(out_path)
    V0, F0 = load(files / "ellipsoid.obj")
    assert Vs.shape == V0.shape and np.array_equal(F, F0)
    assert np.allclose(np.linalg.norm(Vs, axis=1), 1.0, atol=1e-6)
    assert np.all(orientation_determinants(Vs, F) > 0)


@pytest.mark.slow_nojit
def test_fit_info_and_resume(files, tmp_path, capsys):
    model = tmp_path / "fit.npz"
    argv = ["fit", files / "ellipsoid.obj", "-o", model, *TINY_FIT]
    code, out, err = run(argv, capsys)
    assert code == 0 and err == ""
    # the checkpoint goes once the model is saved, and no lock or temporary file stays
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.npz"]
    argv += ["--keep-checkpoint"]
    code, out, err = run(argv, capsys)
    assert code == 0 and err == "" and "checkpoint kept" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.ckpt.npz", "fit.npz"]
    S = SphericalNeuralSurface.load(model)
    assert (S.net.width, S.net.depth) == (16, 1)
    fit = S.metadata["fit"]
    assert fit["steps"] == 5 and S.metadata["n_vertices"] == 162
    assert fit["position_relative"] < 0.05                  # in the mesh's units, roughly
    assert S.metadata["source"] == str(files / "ellipsoid.obj")
    y = S(np.eye(3))                                         # the axes land near the ellipsoid
    assert np.allclose(np.abs(np.diag(y)), [1.0, 1.3, 0.7], atol=0.2)

    assert "measured detail" in out and "chosen input_scale = 4 (smooth target)" in out
    assert "chosen lr = 0.0001" in out and "note: the step budget" in out

    code, out, _ = run(["info", model], capsys)
    assert code == 0 and "fit: 5 steps" in out and '"width": 16' in out
    assert "chosen warmup = 50 (smooth target)" in out and "note: the step budget" in out

    # --input-scale reaches the initialisation (W0 ~ N(0, (scale / sqrt(3))^2)) and the record
    wide = tmp_path / "wide.npz"
    code, _, err = run(["fit", files / "ellipsoid.obj", "-o", wide, *TINY_FIT,
                        "--input-scale", "7"], capsys)
    assert code == 0, err
    W = SphericalNeuralSurface.load(wide)
    assert W.metadata["fit"]["options"]["input_scale"] == 7.0
    assert 0.75 < W.net.W0.std() / (7 / np.sqrt(3)) < 1.25
    assert 0.75 < S.net.W0.std() / (4 / np.sqrt(3)) < 1.25  # the default, 4

    # resuming the finished fit from its checkpoint gives the same model
    code, _, err = run(argv + ["--resume"], capsys)
    assert code == 0, err
    assert np.array_equal(SphericalNeuralSurface.load(model).net.theta, S.net.theta)


def test_fit_interrupted_exits_130(files, tmp_path, capsys, monkeypatch):
    import sns_np.surface

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(sns_np.surface, "fit_mesh", interrupted)
    code, _, err = run(["fit", files / "ellipsoid.obj", "-o", tmp_path / "m.npz", "--quiet"],
                       capsys)
    assert code == 130 and err.strip() == "sns-np fit: interrupted"
    assert list(tmp_path.iterdir()) == []


def test_eigen_writes_modes(files, tmp_path, capsys):
    out_path = tmp_path / "modes.ply"
    code, out, err = run(["eigen", files / "model.npz", "-k", 3, "--level", 2, "-o", out_path,
                          "--quiet"], capsys)
    assert code == 0 and err == ""
    lam = [float(line.split("=")[1]) for line in out.splitlines() if line.startswith("lambda_")]
    assert len(lam) == 3 and 0 < lam[0] <= lam[1] <= lam[2]
    import meshio
    fields = meshio.read(out_path).point_data
    assert {"mode_1", "mode_2", "mode_3"} <= set(fields)


@pytest.mark.slow_nojit
def test_demo_tiny(tmp_path, capsys):
    out_path = tmp_path / "demo.npz"
    code, out, _ = run(["demo", "--level", 1, "--steps", 2, "--width", 8, "--depth", 1,
                        "--quiet", "-o", out_path], capsys)
    assert code == 0
    assert "Gauss-Bonnet" in out and out_path.exists()
    assert SphericalNeuralSurface.load(out_path).metadata["fit"]["steps"] == 2


# ------------------------------------------------------------------------------ bad input

# (argv with {d} for the input folder and {o} for the output folder, words the message must hold)
BAD = {
    "missing mesh": ("fit {d}/nope.obj -o {o}/m.npz", "not found"),
    "unsupported format": ("fit {d}/mesh.xyz -o {o}/m.npz", "unsupported mesh format"),
    "open mesh": ("fit {d}/open.obj -o {o}/m.npz", "boundary edge"),
    "open mesh, embed": ("embed {d}/open.obj -o {o}/s.obj", "boundary edge"),
    "pinched vertex": ("fit {d}/pinched.obj -o {o}/m.npz", "non-manifold"),
    "torus": ("embed {d}/torus.obj -o {o}/s.obj", "genus 1"),
    "inward faces": ("fit {d}/inward.obj -o {o}/m.npz", "faces inwards"),
    "NaN coordinates": ("fit {d}/nan.obj -o {o}/m.npz", "non-finite"),
    "missing model": ("info {d}/nope.npz", "does not exist"),
    "garbage model": ("eval {d}/garbage.npz -o {o}/s.ply", "not a readable .npz"),
    "truncated model": ("info {d}/truncated.npz", "not a readable .npz"),
    "not a model": ("eval {d}/not_a_model.npz -o {o}/s.ply", "not an sns_np model"),
    "future model": ("info {d}/future.npz", "version 99 is not supported"),
    "a mesh as model": ("info {d}/ellipsoid.obj", "not a readable .npz"),
    "zero steps": ("fit {d}/ellipsoid.obj -o {o}/m.npz --steps 0", "--steps"),
    "width not a number": ("fit {d}/ellipsoid.obj -o {o}/m.npz --width abc", "--width"),
    "negative time budget": ("fit {d}/ellipsoid.obj -o {o}/m.npz --time-budget -1",
                             "--time-budget"),
    "unknown optimizer": ("fit {d}/ellipsoid.obj -o {o}/m.npz --optimizer lbfgs",
                          "--optimizer"),
    "negative normal weight": ("fit {d}/ellipsoid.obj -o {o}/m.npz --normal-weight -1 "
                               "--steps 1 --quiet", "normal_weight"),
    "negative input scale": ("fit {d}/ellipsoid.obj -o {o}/m.npz --input-scale -2",
                             "--input-scale"),
    "model not .npz": ("fit {d}/ellipsoid.obj -o {o}/m.txt", "must end in"),
    "creases not an angle": ("fit {d}/ellipsoid.obj -o {o}/m.npz --creases sharp", "--creases"),
    "creases out of range": ("fit {d}/ellipsoid.obj -o {o}/m.npz --creases 270", "(0, 180]"),
    "no output folder": ("eval {d}/model.npz -o {o}/no/s.ply", "does not exist"),
    "checkpoint folder": ("fit {d}/ellipsoid.obj -o {o}/m.npz --checkpoint {o}/no/c.npz",
                          "does not exist"),
    "nothing to resume": ("fit {d}/ellipsoid.obj -o {o}/m.npz --resume", "no checkpoint"),
    "eval level": ("eval {d}/model.npz -o {o}/s.ply --level 9", "--level"),
    "eigen level": ("eigen {d}/model.npz -o {o}/s.ply --level 30", "--level"),
    "eigen k": ("eigen {d}/model.npz -k 0", "-k"),
    "eigen output": ("eigen {d}/model.npz -o {o}/s.obj", "must end in"),
    "embed output": ("embed {d}/ellipsoid.obj -o {o}/s.xyz", "must end in"),
    "demo output": ("demo -o {o}/m.txt", "must end in"),
    "missing arguments": ("fit {d}/ellipsoid.obj", "-o/--output"),
    "unknown command": ("fitt {d}/ellipsoid.obj", "invalid choice"),
    "batch, no output parent": ("batch fit {d}/ellipsoid.obj -o {o}/no/out", "does not exist"),
    "batch, name clash": ("batch fit {d}/ellipsoid.obj {d}/sub/ellipsoid.obj -o {o}/out",
                          "same output ellipsoid.npz"),
    "batch, workers and scheduler": ("batch fit {d}/ellipsoid.obj -o {o}/out --workers 2 "
                                     "--scheduler tcp://127.0.0.1:1", "--workers applies"),
    "batch, zero steps": ("batch fit {d}/ellipsoid.obj -o {o}/out --steps 0", "--steps"),
    "batch spectrum, output": ("batch spectrum {d}/model.npz -k 3 -o {o}/t.txt",
                               "must end in .csv"),
    "batch spectrum, no k": ("batch spectrum {d}/model.npz -o {o}/t.csv", "-k"),
    "batch, no subcommand": ("batch", "BATCH_COMMAND"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_one_line_status_2_no_output(case, files, tmp_path, capsys):
    template, words = BAD[case]
    argv = template.format(d=files, o=tmp_path).split()
    before = sorted(files.iterdir())
    code, out, err = run(argv, capsys)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("sns-np") and "error:" in lines[0]
    assert words in lines[0]
    assert list(tmp_path.iterdir()) == []                   # nothing written, not even a temp
    assert sorted(files.iterdir()) == before


def test_choice_lines_name_what_was_measured_and_chosen():
    from sns_np.cli import _choice_lines

    lines = _choice_lines({"detail": {"value": 0.046, "why": "detailed"},
                           "lr": {"value": 0.004, "why": "detailed target"},
                           "steps": {"value": 1598, "why": "as many as fit"},
                           "bad": "not a dict", "esc": {"value": "\x1b[2J", "why": "x"}})
    assert lines[0] == "  measured detail = 0.046 (detailed)"
    assert lines[1] == "  chosen lr = 0.004 (detailed target)"
    assert lines[2] == "  chosen steps = 1598 (as many as fit)"
    assert len(lines) == 4 and "\x1b" not in lines[3]      # escapes are not printed raw
