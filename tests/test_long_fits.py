"""Long fits and crashes: signals, checkpoint cadence, divergence, locks and stale files."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from sns_np import SphericalNeuralSurface
from sns_np._atomic import OutputBusyError, exclusive
from sns_np._signals import deferred_signals
from sns_np.errors import DivergenceError, FitInterrupted, ModelFileError
from sns_np.mesh import write_mesh
from sns_np.nn import optim
from sns_np.shapes import Ellipsoid
from sns_np.surface import fit_shape

from .conftest import run_cli

TINY = dict(width=16, depth=1, batch=256, n_eval=500, progress=False, dtype="float64")
E = Ellipsoid(1.0, 1.3, 0.7)


@pytest.fixture(scope="module")
def mesh(tmp_path_factory):
    path = tmp_path_factory.mktemp("long_fits") / "ellipsoid.obj"
    write_mesh(path, *E.mesh(2))                    # 162 vertices
    return path


def _step_of(path):
    with np.load(path) as data:
        return int(data["checkpoint.step"])


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_saves_the_checkpoint_and_resume_is_exact(tmp_path, sig):
    S_full, _ = fit_shape(E, steps=40, **TINY)
    ck = tmp_path / "ck.npz"
    before = signal.getsignal(signal.SIGINT)    # default_int_handler, or SIG_IGN under nohup

    def send(step, info):
        if step == 20:
            os.kill(os.getpid(), sig)

    with pytest.raises(FitInterrupted) as caught:
        fit_shape(E, steps=40, checkpoint=ck, callback=send, history_every=10, **TINY)
    exc = caught.value
    assert isinstance(exc, KeyboardInterrupt)
    assert (exc.step, exc.checkpoint, exc.signal_name) == (20, ck, signal.Signals(sig).name)
    assert str(ck) in str(exc) and "resume=True" in str(exc)
    assert _step_of(ck) == 20 and sorted(p.name for p in tmp_path.iterdir()) == ["ck.npz"]
    # the handlers in place before the fit are back
    assert signal.getsignal(signal.SIGINT) is before
    S_res, r = fit_shape(E, steps=40, checkpoint=ck, resume=True, **TINY)
    assert r.steps == 40 and np.array_equal(S_res.net.pack(), S_full.net.pack())


def test_an_interrupt_inside_an_update_waits_for_its_end(tmp_path, monkeypatch):
    """Ctrl-C arriving in the middle of the optimiser's update: the update completes, the
    checkpoint holds that whole step, and resuming reproduces the uninterrupted fit."""
    S_full, _ = fit_shape(E, steps=30, **TINY)
    original = optim.Adam.step
    calls = []

    def step_with_interrupt(self, theta, grad):
        calls.append(1)
        if len(calls) == 13:
            theta[: len(theta) // 2] -= 0.0         # touch the parameters, then the signal
            os.kill(os.getpid(), signal.SIGINT)     # lands here, in the middle of the update
        return original(self, theta, grad)

    monkeypatch.setattr(optim.Adam, "step", step_with_interrupt)
    ck = tmp_path / "ck.npz"
    with pytest.raises(FitInterrupted) as caught:
        fit_shape(E, steps=30, checkpoint=ck, **TINY)
    assert caught.value.step == 13 and _step_of(ck) == 13
    monkeypatch.setattr(optim.Adam, "step", original)
    S_res, _ = fit_shape(E, steps=30, checkpoint=ck, resume=True, **TINY)
    assert np.array_equal(S_res.net.pack(), S_full.net.pack())


def test_a_second_signal_stops_at_once():
    before = signal.getsignal(signal.SIGINT)    # default_int_handler, or SIG_IGN under nohup
    with pytest.raises(KeyboardInterrupt):
        with deferred_signals() as guard:
            os.kill(os.getpid(), signal.SIGINT)
            assert guard.received == "SIGINT"
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)                          # pragma: no cover - interrupted before
    assert signal.getsignal(signal.SIGINT) is before


def test_checkpoint_cadence_by_time_and_by_steps(tmp_path):
    ck = tmp_path / "ck.npz"
    seen = {}

    def look(step, info):
        seen[step] = _step_of(ck) if ck.exists() else None

    # by time: a 1 ms cadence writes after every step, whatever the step cadence
    fit_shape(E, steps=30, checkpoint=ck, checkpoint_every=10**6, checkpoint_seconds=1e-3,
              callback=look, history_every=10, **TINY)
    assert seen == {10: 9, 20: 19, 30: 29}
    # by steps, with the clock far away
    ck.unlink()
    seen.clear()
    fit_shape(E, steps=30, checkpoint=ck, checkpoint_every=10, checkpoint_seconds=3600,
              callback=look, history_every=5, **TINY)
    assert seen == {5: None, 10: None, 15: 10, 20: 10, 25: 20, 30: 20}
    assert _step_of(ck) == 30                        # and at the end
    for bad, match in ((dict(checkpoint_seconds=0), "checkpoint_seconds"),
                       (dict(checkpoint_every=0), "checkpoint_every"),
                       (dict(checkpoint=tmp_path / "ck.zip"), "must end in .npz"),
                       (dict(checkpoint=tmp_path / "no" / "ck.npz"), "does not exist")):
        with pytest.raises(ValueError, match=match):
            fit_shape(E, steps=5, **dict(dict(TINY, checkpoint=ck), **bad))


def test_divergence_leaves_the_checkpoint_it_names(tmp_path):
    ck = tmp_path / "ck.npz"

    def poison(step, info):
        if step == 10:
            info["net"].theta[0] = np.nan

    with pytest.raises(DivergenceError, match="diverged at step 10") as caught:
        fit_shape(E, steps=50, checkpoint=ck, checkpoint_every=10**6, callback=poison,
                  history_every=10, **TINY)
    assert repr(str(ck)) in str(caught.value) and _step_of(ck) == 10


def test_a_checkpoint_of_other_soap_matrices_is_refused_with_its_path(tmp_path):
    """A SOAP state written for other matrices (an earlier version preconditioned only the
    hidden ones) names the checkpoint and what to do, before any step."""
    ck = tmp_path / "ck.npz"
    fit_shape(E, steps=8, checkpoint=ck, optimizer="soap", lr=1e-3, **TINY)
    with np.load(ck) as data:
        arrays = dict(data)
    arrays["opt.L0"] = np.zeros((1, 4, 4))
    np.savez(ck, **arrays)
    with pytest.raises(ModelFileError, match="optimiser state that this fit's optimiser "
                       "cannot take.*L0.*delete it"):
        fit_shape(E, steps=8, checkpoint=ck, resume=True, optimizer="soap", lr=1e-3, **TINY)


def test_a_second_fit_on_the_same_checkpoint_is_refused(tmp_path):
    ck = tmp_path / "ck.npz"
    with exclusive(ck) as lock:
        assert lock.exists() and str(os.getpid()) in lock.read_text()
        with pytest.raises(OutputBusyError, match="another process"):
            fit_shape(E, steps=5, checkpoint=ck, **TINY)
    assert not lock.exists()
    fit_shape(E, steps=5, checkpoint=ck, **TINY)     # free again
    assert ck.exists() and not (tmp_path / "ck.npz.lock").exists()


def test_cli_fit_refuses_an_output_in_use(mesh, tmp_path, capsys):
    out = tmp_path / "m.npz"
    with exclusive(out):
        code, _, err = run_cli(["fit", mesh, "-o", out, "--steps", "2",
                                "--width", "8", "--depth", "1", "--quiet"], capsys)
    assert code == 2 and "being written by another process" in err and "m.npz.lock" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_cli_output_suffix_in_any_case(mesh, tmp_path, capsys):
    out = tmp_path / "m.NPZ"
    code, _, err = run_cli(["fit", mesh, "-o", out, "--steps", "2",
                            "--width", "8", "--depth", "1", "--quiet"], capsys)
    assert code == 0, err
    assert SphericalNeuralSurface.load(out).net.width == 8


def _start_fit(mesh, out, *extra):
    argv = [sys.executable, "-m", "sns_np.cli", "fit", str(mesh), "-o", str(out),
            "--width", "8", "--depth", "1", "--batch", "128", "--time-budget", "120",
            "--checkpoint-every", "0.2", "--quiet", *extra]
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(path, proc, timeout=120.0):
    t = time.monotonic()
    while not path.exists():
        if proc.poll() is not None or time.monotonic() - t > timeout:
            proc.kill()
            raise AssertionError(f"no {path.name} appeared: {proc.communicate()}")
        time.sleep(0.05)
    time.sleep(0.5)                                  # a few more steps and saves


@pytest.mark.slow_nojit
def test_cli_sigterm_then_resume_then_kill_9(mesh, tmp_path):
    """The whole story in separate processes: SIGTERM saves and says how to go on; a killed
    fit (kill -9) leaves a checkpoint at most one cadence old; stale temporaries and the dead
    fit's lock are cleaned up by the next run."""
    out, ck = tmp_path / "m.npz", tmp_path / "m.ckpt.npz"
    proc = _start_fit(mesh, out)
    _wait_for(ck, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "interrupted by SIGTERM after step" in err and "--resume" in err and str(ck) in err
    held = _step_of(ck)
    assert held > 0 and sorted(p.name for p in tmp_path.iterdir()) == ["m.ckpt.npz"]

    # kill -9: the checkpoint survives, plus whatever a killed writer leaves behind
    proc = _start_fit(mesh, out, "--resume")
    t_kill = time.monotonic()
    while _step_of(ck) <= held and time.monotonic() - t_kill < 60:
        time.sleep(0.1)
    proc.kill()
    proc.communicate(timeout=60)
    assert _step_of(ck) > held
    stale = [tmp_path / "m.npz.0badc0de.tmp", tmp_path / "m.ckpt.npz.0badc0de.tmp"]
    for s in stale:
        s.write_bytes(b"half a file")
    (tmp_path / "m.npz.lock").write_text("process 1 on elsewhere\n")   # a dead holder's lock

    # the next run takes the dead fit's lock over, removes the stale files and goes on
    proc = _start_fit(mesh, out, "--resume")
    killed_at = _step_of(ck)
    t = time.monotonic()
    while _step_of(ck) <= killed_at and time.monotonic() - t < 60:
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "removed" in err and "m.npz.0badc0de.tmp" in err
    assert _step_of(ck) > killed_at
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.ckpt.npz"]


def test_a_fit_in_a_worker_thread_leaves_signals_alone(tmp_path):
    """Handlers can only be set from the main thread: a fit in another thread (a Dask worker,
    for instance) runs with the signals as they are, and still checkpoints."""
    import threading
    result = {}

    def work():
        try:
            result["report"] = fit_shape(E, steps=5, checkpoint=tmp_path / "ck.npz", **TINY)[1]
        except BaseException as exc:                 # pragma: no cover - reported below
            result["error"] = exc

    before = signal.getsignal(signal.SIGTERM)
    thread = threading.Thread(target=work)
    thread.start()
    thread.join()
    assert "error" not in result, result.get("error")
    assert result["report"].steps == 5 and _step_of(tmp_path / "ck.npz") == 5
    assert signal.getsignal(signal.SIGTERM) is before
