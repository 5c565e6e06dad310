"""The ``sns-np heat`` and ``sns-np mcf`` subcommands."""

import json

import numpy as np
import pytest

from sns_np.cli import main
from sns_np.mesh import load
from sns_np.shapes import Sphere
from sns_np.surface import SphericalNeuralSurface

pytestmark = pytest.mark.slow_nojit  # fits and flows run the network kernels


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    # a fitted unit sphere, a little smaller than the sphere: the heat tests' 180 points keep
    # dt = 0.01 inside the explicit limit A / (2 pi N) with margin (200 were on the edge)
    S, _ = SphericalNeuralSurface.fit_shape(Sphere(), width=16, depth=1, steps=400, batch=512,
                                            progress=False, n_eval=256, seed=0, lr=1e-3,
                                            normal_weight=1e-4)
    path = tmp_path_factory.mktemp("model") / "sphere.npz"
    S.save(path)
    return path


def test_heat_network_writes_snapshots(model, tmp_path, capsys):
    out = tmp_path / "heat"
    rc = main(["heat", str(model), "--field", "sh:1,0", "--t-end", "0.04", "--dt", "0.01",
               "--snapshots", "2", "--points", "180", "--refit-steps", "2", "--level", "2",
               "-o", str(out)])
    assert rc == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["flow.json", "heat_000.npz", "heat_000.ply", "heat_001.npz",
                     "heat_001.ply", "heat_002.npz", "heat_002.ply"]
    info = json.loads((out / "flow.json").read_text())
    assert info["times"] == pytest.approx([0.0, 0.02, 0.04]) and info["stopped"] == "t_end"
    V, F = load(out / "heat_002.ply")
    assert V.shape == (162, 3)
    assert "wrote" in capsys.readouterr().out
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_heat_spectral_decays(model, tmp_path):
    import meshio
    out = tmp_path / "spec"
    rc = main(["heat", str(model), "--field", "z", "--t-end", "0.3", "--method", "spectral",
               "-k", "3", "--snapshots", "1", "--level", "2", "-o", str(out), "--quiet"])
    assert rc == 0
    f0 = meshio.read(out / "heat_000.ply").point_data["f"]
    f1 = meshio.read(out / "heat_001.ply").point_data["f"]
    # z on the (fitted) unit sphere is an l = 1 harmonic: it decays by exp(-2 t)
    ratio = float(f1 @ f0 / (f0 @ f0))
    assert abs(ratio / np.exp(-0.6) - 1) < 0.02


def test_mcf_writes_models_and_meshes(model, tmp_path, capsys):
    out = tmp_path / "mcf"
    rc = main(["mcf", str(model), "--t-end", "0.01", "--dt", "0.0025", "--snapshots", "2",
               "--points", "300", "--refit-steps", "1", "--level", "2", "-o", str(out),
               "--quiet"])
    assert rc == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["flow.json"] + [f"mcf_{j:03d}.{e}" for j in range(3) for e in ("npz", "ply")]
    S0 = SphericalNeuralSurface.load(out / "mcf_000.npz")
    S2 = SphericalNeuralSurface.load(out / "mcf_002.npz")
    p = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    r0, r2 = np.linalg.norm(S0(p), axis=1), np.linalg.norm(S2(p), axis=1)
    np.testing.assert_allclose(r2 ** 2, r0 ** 2 - 4 * 0.01, atol=2e-3)
    assert "areas:" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["heat", "{model}", "--field", "sh:1", "--t-end", "1", "-o", "{out}"], "sh:L,M"),
    (["heat", "{model}", "--field", "w", "--t-end", "1", "-o", "{out}"], "expected 'sh:L,M'"),
    (["heat", "{model}", "--field", "x", "--t-end", "1", "--dt", "0.1", "--points", "5000",
      "-o", "{out}"], "stability limit dt <= h^2 / (2 pi)"),
    (["mcf", "{model}", "--t-end", "1", "--dt", "0.1", "--points", "5000", "-o", "{out}"],
     "stability limit"),
    (["mcf", "{model}", "--t-end", "1", "-o", "{tmp}/missing/out"], "does not exist"),
    (["mcf", "{model}", "--t-end", "1", "-o", "{full}"], "already exists"),
    (["mcf", "{tmp}/nothing.npz", "--t-end", "1", "-o", "{out}"], "nothing.npz"),
])
def test_bad_input_exits_2(model, tmp_path, capsys, argv, message):
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("x")
    fill = dict(model=model, out=tmp_path / "out", tmp=tmp_path, full=full)
    rc = main([a.format(**fill) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    assert (full / "keep.txt").read_text() == "x"


@pytest.mark.parametrize("scheme, refits", [("euler", 4), ("heun", 8), ("midpoint", 8)])
def test_mcf_scheme_flag(model, tmp_path, capsys, scheme, refits):
    out = tmp_path / "mcf"
    rc = main(["mcf", str(model), "--t-end", "0.01", "--dt", "0.0025", "--snapshots", "1",
               "--points", "300", "--refit-steps", "1", "--level", "1", "--scheme", scheme,
               "-o", str(out), "--quiet"])
    assert rc == 0
    info = json.loads((out / "flow.json").read_text())
    assert info["scheme"] == scheme and info["refits"] == refits and info["steps"] == 4
    assert f"({refits} refits, scheme {scheme})" in capsys.readouterr().out


def test_heat_scheme_flag(model, tmp_path, capsys):
    out = tmp_path / "heat"
    rc = main(["heat", str(model), "--field", "sh:1,0", "--t-end", "0.02", "--dt", "0.01",
               "--snapshots", "1", "--points", "180", "--refit-steps", "2", "--level", "1",
               "--scheme", "euler", "-o", str(out), "--quiet"])
    assert rc == 0
    info = json.loads((out / "flow.json").read_text())["info"]
    assert info["scheme"] == "euler" and info["refits"] == 2
    assert "(2 refits, scheme euler)" in capsys.readouterr().out


def test_scheme_flag_default_and_choices(capsys):
    from sns_np.cli import build_parser
    for cmd in ("mcf", "heat"):
        sub = build_parser()._subparsers._group_actions[0].choices[cmd]
        action = next(a for a in sub._actions if "--scheme" in a.option_strings)
        assert action.default == "heun" and list(action.choices) == ["heun", "midpoint", "euler"]
        assert "(default: heun)" in " ".join(sub.format_help().split())
    with pytest.raises(SystemExit) as exc:
        main(["mcf", "m.npz", "--t-end", "1", "--scheme", "rk4", "-o", "x"])
    assert exc.value.code == 2 and "invalid choice: 'rk4'" in capsys.readouterr().err


def test_mcf_divergence_keeps_last_good_snapshot(model, tmp_path, capsys):
    out = tmp_path / "mcf"
    rc = main(["mcf", str(model), "--t-end", "0.01", "--dt", "0.002", "--snapshots", "5",
               "--points", "200", "--refit-steps", "3", "--lr", "1000", "--level", "1",
               "-o", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "diverged" in err and "last good surface" in err
    info = json.loads((out / "flow.json").read_text())
    assert info["stopped"].startswith("mean curvature flow diverged")
    assert info["times"][0] == 0 and info["times"][-1] < 0.01
    S = SphericalNeuralSurface.load(out / f"mcf_{len(info['times']) - 1:03d}.npz")
    assert np.all(np.isfinite(S.net.theta))
