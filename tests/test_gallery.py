"""The figure gallery script (examples/gallery.py): its quick mode writes four real images, and
without matplotlib it names the extra to install."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPT = EXAMPLES / "gallery.py"
NAMES = ("gallery_spot_mean_curvature.png", "gallery_eigenmodes.png", "gallery_heat_flow.png",
         "gallery_mcf.png")


def _load_gallery(monkeypatch):
    if not SCRIPT.is_file():
        pytest.skip("examples/ not present")
    monkeypatch.syspath_prepend(str(EXAMPLES))              # the script imports _common
    spec = importlib.util.spec_from_file_location("sns_np_gallery_example", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.slow_nojit
def test_quick_gallery_writes_four_nontrivial_pngs(tmp_path):
    image = pytest.importorskip("matplotlib.image")
    if not SCRIPT.is_file():
        pytest.skip("examples/ not present")
    out = tmp_path / "gallery"
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(out)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == sorted(NAMES)   # no temporary files left
    for name in NAMES:
        assert f"wrote {out / name}" in proc.stdout
        pixels = image.imread(out / name)
        assert pixels.ndim == 3 and pixels.shape[0] > 200 and pixels.shape[1] > 300, name
        rgb = pixels[..., :3].reshape(-1, 3)
        colours = np.unique(np.round(rgb * 255).astype(np.uint8), axis=0)
        assert len(colours) > 200, f"{name}: only {len(colours)} colours"
        white = np.all(rgb > 0.98, axis=1).mean()
        assert 0.2 < white < 0.97, f"{name}: {white:.0%} of the pixels are white"
    # nothing written beside the output folder
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gallery"]


def test_gallery_without_matplotlib_names_the_extra(monkeypatch, tmp_path, capsys):
    gallery = _load_gallery(monkeypatch)
    monkeypatch.setitem(sys.modules, "matplotlib", None)    # import matplotlib -> ImportError
    with pytest.raises(ImportError, match=r"sns-np\[plots\]"):
        gallery.need_matplotlib()
    with pytest.raises(SystemExit) as exc:
        gallery.main(["--quick", "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "matplotlib" in err and "sns-np[plots]" in err
    assert not (tmp_path / "out").exists()


def test_gallery_refuses_quick_with_a_model(monkeypatch, capsys):
    gallery = _load_gallery(monkeypatch)
    with pytest.raises(SystemExit) as exc:
        gallery.main(["--quick", "--model", "spot.npz"])
    assert exc.value.code == 2
    assert "--quick uses its own small surface" in capsys.readouterr().err


def test_hot_spot_jets_match_central_differences(monkeypatch):
    from sns_np.testing import check_jet
    gallery = _load_gallery(monkeypatch)
    bump = gallery.GaussianBump(center=(0.2, -0.1, 0.5), width=0.4)
    x = np.random.default_rng(0).normal(scale=0.5, size=(20, 3))
    err = check_jet(bump, x, order=2)
    assert err["J"] < 1e-8 and err["D2"] < 1e-7, err
    assert np.allclose(bump.jet(np.array([[0.2, -0.1, 0.5]])), 1.0)
