"""Collections of shapes on Dask (sns_np.batch): tables, a real LocalCluster of processes with a
bad mesh, reproducibility, a rerun that skips, a worker killed mid-fit, and the command line
against a scheduler and a worker started as separate processes.

The cluster tests need the extra ``pip install "sns-np[distributed]"`` and skip without it.
"""

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from sns_np.batch import FIT_COLUMNS, Table, fit_many, local_layout, spectra_many
from sns_np.mesh import check, icosphere, load, write_mesh
from sns_np.shapes import Ellipsoid

from .conftest import run_cli

NEEDS_DASK = "needs the optional extra 'distributed' (pip install \"sns-np[distributed]\")"
TINY = dict(width=8, depth=1, steps=10, batch=64, n_eval=100, dtype="float64", lr=1e-3,
            input_scale=4.0, warmup=5)          # all given: no detail probe
#: cluster tests start worker processes: too slow without the JIT
pytestmark = pytest.mark.slow_nojit


def _distributed():
    return pytest.importorskip("distributed", reason=NEEDS_DASK)


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    d = tmp_path_factory.mktemp("batch_meshes")
    write_mesh(d / "egg.obj", *Ellipsoid(1.0, 1.3, 0.7).mesh(1))
    write_mesh(d / "pebble.obj", *Ellipsoid(1.0, 0.8, 0.6).mesh(1))
    P, T = icosphere(1)
    write_mesh(d / "open.obj", P, T[1:])                    # one face missing
    return d


@pytest.fixture(scope="module")
def client():
    distributed = _distributed()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as c:
        yield c


# ------------------------------------------------------------------------------ no cluster

def test_table_round_trips_csv_and_json(tmp_path):
    rows = [{"name": "a", "status": "done", "steps": 3, "x": 0.1 + 0.2, "message": ""},
            {"name": "b,c", "status": "error", "steps": None, "x": float("nan"),
             "message": 'bad "mesh"'}]
    t = Table(rows, meta={"k": 2})
    a = Table.read(t.to_csv(tmp_path / "t.csv"))
    b = Table.read(t.to_json(tmp_path / "t.json"))
    assert a.columns == b.columns == t.columns
    assert a[0] == {"name": "a", "status": "done", "steps": 3, "x": 0.1 + 0.2, "message": None}
    assert a[1]["name"] == "b,c" and a[1]["message"] == 'bad "mesh"' and np.isnan(a[1]["x"])
    assert b[1]["x"] is None and b.meta == {"k": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv", "t.json"]   # no temporaries


def test_local_layout_fills_the_cores_once():
    for cores in (1, 2, 3, 8):
        n, t = local_layout(cores=cores)
        assert n * t == cores and t == 1
    assert local_layout(1, cores=2) == (1, 2)
    with pytest.raises(ValueError, match="workers"):
        local_layout(0)


def test_name_clashes_are_refused_before_any_work(meshes, tmp_path):
    (tmp_path / "other").mkdir()
    twin = tmp_path / "other" / "EGG.obj"
    twin.write_text((meshes / "egg.obj").read_text())
    with pytest.raises(ValueError, match="same output egg.npz"):
        fit_many([meshes / "egg.obj", twin], tmp_path / "out", **TINY)
    assert not (tmp_path / "out").exists()
    with pytest.raises(TypeError, match="sets checkpoint"):
        fit_many([meshes / "egg.obj"], tmp_path / "out", checkpoint="x.npz")
    with pytest.raises(TypeError, match="unknown fitting option"):
        fit_many([meshes / "egg.obj"], tmp_path / "out", widht=8)


def test_a_missing_extra_is_named(meshes, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)     # as if not installed
    with pytest.raises(ImportError, match=r'sns-np\[distributed\]'):
        fit_many([meshes / "egg.obj"], tmp_path / "out", progress=False, **TINY)
    with pytest.raises(ImportError, match=r'sns-np\[distributed\]'):
        spectra_many([meshes / "egg.npz"], 3, progress=False)
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------ LocalCluster

def test_batch_with_a_bad_mesh_reproducible_and_rerun_skips(meshes, tmp_path, client):
    from sns_np.batch import limit_threads
    from sns_np.surface import SphericalNeuralSurface, fit_mesh

    out = tmp_path / "out"
    paths = [meshes / "egg.obj", meshes / "open.obj", meshes / "pebble.obj"]
    t = fit_many(paths, out, client=client, progress=False, **TINY)
    assert t.columns == FIT_COLUMNS
    assert t.column("status") == ["done", "error", "done"]
    with pytest.raises(ValueError) as bad:
        check(*load(meshes / "open.obj"))
    assert t[1]["message"] == str(bad.value)                 # check's one-line message
    assert t[0]["steps"] == 10 and t[0]["resumed_from"] is None
    assert json.loads(t[0]["threads"]) == {"blas": 1, "numba": 1}
    assert sorted(p.name for p in out.iterdir()) == ["egg.npz", "pebble.npz", "summary.csv",
                                                     "summary.json"]
    on_disk = Table.read(out / "summary.csv")
    assert on_disk.column("status") == t.column("status")
    assert Table.read(out / "summary.json").meta["counts"] == {"done": 2, "skipped": 0,
                                                               "error": 1}
    # the batch's model is the direct fit's, bit for bit, at the same thread count
    S_batch = SphericalNeuralSurface.load(out / "egg.npz")
    with limit_threads(1):
        S_direct, _ = fit_mesh(*load(meshes / "egg.obj"), progress=False, **TINY)
    assert np.array_equal(S_batch.net.pack(), S_direct.net.pack())
    fit = S_batch.metadata["fit"]                # the row carries the model's own figures
    assert t[0]["two_sided_distance_relative"] == fit["two_sided_distance_relative"]
    assert fit["two_sided_distance_relative"] != fit["distance_relative"]   # both sides
    # a rerun skips complete outputs and fits nothing again
    stamp = (out / "egg.npz").stat().st_mtime_ns
    again = fit_many(paths, out, client=client, progress=False, **TINY)
    assert again.column("status") == ["skipped", "error", "skipped"]
    assert again[0]["steps"] == 10 and (out / "egg.npz").stat().st_mtime_ns == stamp
    # other options: refused before any work, naming the file
    with pytest.raises(ValueError, match=r"egg.npz exists and it was fitted with other "
                                         r"options \(steps 10 -> 11\)"):
        fit_many(paths, out, client=client, progress=False, **dict(TINY, steps=11))


def test_spectra_many_matches_eigenmodes(meshes, tmp_path, client):
    from sns_np.spectral import eigenmodes
    from sns_np.surface import SphericalNeuralSurface

    t = fit_many([meshes / "egg.obj"], tmp_path, client=client, progress=False, **TINY)
    model = t[0]["output"]
    s = spectra_many([model, tmp_path / "missing.npz"], 4, client=client, progress=False,
                     out=tmp_path / "spectra.csv", L=6)
    assert s.column("status") == ["done", "error"] and "missing.npz" in s[1]["message"]
    direct = eigenmodes(SphericalNeuralSurface.load(model), 4, L=6).eigenvalues
    assert np.allclose([s[0][f"lambda_{i}"] for i in range(1, 5)], direct, rtol=1e-12)
    back = Table.read(tmp_path / "spectra.json")
    assert back.meta["k"] == 4 and back[0]["L"] == 6


@pytest.mark.slow
def test_a_worker_killed_mid_fit_is_rescheduled_and_resumes(meshes, tmp_path, client):
    """kill -9 of the worker process running a fit: Dask reschedules the task, which resumes
    from the checkpoint, and the model is the uninterrupted fit's, bit for bit."""
    from sns_np.batch import limit_threads
    from sns_np.surface import SphericalNeuralSurface, fit_mesh

    opts = dict(TINY, width=16, steps=1500)
    out = tmp_path / "out"
    result = {}
    runner = threading.Thread(target=lambda: result.setdefault("t", fit_many(
        [meshes / "egg.obj"], out, client=client, progress=False, checkpoint_seconds=0.2,
        **opts)))
    runner.start()
    ckpt = out / "egg.ckpt.npz"
    seen = None
    deadline = time.monotonic() + 180
    while seen is None and time.monotonic() < deadline and runner.is_alive():
        if ckpt.exists():
            try:
                with np.load(ckpt) as data:
                    seen = int(data["checkpoint.step"]) or None
            except Exception:                               # being replaced: look again
                pass
        time.sleep(0.05)
    assert seen, "no checkpoint appeared while the fit ran"
    busy = [w for w, keys in client.processing().items() if keys]
    assert len(busy) == 1
    pid = client.run(os.getpid, workers=busy)[busy[0]]
    os.kill(pid, signal.SIGKILL)
    runner.join(120)
    t = result["t"]
    assert t[0]["status"] == "done", t[0]
    assert t[0]["steps"] == 1500 and t[0]["resumed_from"] >= seen > 0
    assert not ckpt.exists()
    with limit_threads(1):
        S_direct, _ = fit_mesh(*load(meshes / "egg.obj"), progress=False, **opts)
    S = SphericalNeuralSurface.load(out / "egg.npz")
    assert np.array_equal(S.net.pack(), S_direct.net.pack())
    assert S.metadata["batch"]["resumed_from"] == t[0]["resumed_from"]


# ------------------------------------------------------------------------------ command line

@pytest.mark.slow
def test_cli_against_a_scheduler_and_worker_started_apart(meshes, tmp_path):
    _distributed()
    env = dict(os.environ)       # conftest: the workers import the sns_np the tests import
    sfile = tmp_path / "scheduler.json"
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1",
                               "--port", "0", "--dashboard-address", ":0", "--scheduler-file",
                               str(sfile)], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    try:
        deadline = time.monotonic() + 60
        while not sfile.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(0.2)
        address = json.loads(sfile.read_text())["address"]
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address,
                                       "--nthreads", "1", "--nworkers", "1", "--host",
                                       "127.0.0.1", "--no-dashboard"], env=env,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        out = tmp_path / "out"
        cli = [sys.executable, "-m", "sns_np", "batch"]
        fit = subprocess.run(cli + ["fit", meshes / "egg.obj", meshes / "open.obj", "-o", out,
                                    "--scheduler", address, "--steps", "5", "--width", "8",
                                    "--depth", "1", "--batch", "64", "--lr", "1e-3",
                                    "--input-scale", "4"],
                             env=env, capture_output=True, text=True, timeout=180)
        assert fit.returncode == 1, fit.stderr                # the open mesh's row failed
        assert f"at {address}" in fit.stderr and "batch fit 2/2" in fit.stderr
        assert "boundary edge" in fit.stdout
        assert Table.read(out / "summary.csv").column("status") == ["done", "error"]
        spec = subprocess.run(cli + ["spectrum", out / "egg.npz", "-k", "3", "-o",
                                     tmp_path / "table.csv", "--scheduler", address],
                              env=env, capture_output=True, text=True, timeout=180)
        assert spec.returncode == 0, spec.stderr
        t = Table.read(tmp_path / "table.csv")
        assert t[0]["status"] == "done" and t[0]["lambda_3"] > t[0]["lambda_1"] > 0
        assert (tmp_path / "table.json").exists()
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_cli_batch_bad_input_is_one_line_status_2(meshes, tmp_path, capsys):
    code, out, err = run_cli(["batch", "fit", meshes / "egg.obj", "-o", tmp_path / "no" / "d",
                              "--steps", "2"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "does not exist" in err
    code, out, err = run_cli(["batch", "spectrum", meshes / "egg.npz", "-k", "2", "-o",
                              tmp_path / "t.txt"], capsys)
    assert code == 2 and "must end in .csv" in err
    assert list(tmp_path.iterdir()) == []
