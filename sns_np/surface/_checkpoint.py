"""A fit's checkpoint: when it is written, what it must match to be resumed, and the file."""

from __future__ import annotations

import json
import time

import numpy as np

from .._npz import load_npz, save_npz
from .._validation import check_output_file, check_positive_float, check_positive_int
from ..errors import ModelFileError
from ._targets import _fingerprint
from .model import SphericalNeuralSurface


class _CheckpointCadence:
    """When a fit writes its checkpoint: every ``every`` steps or ``seconds`` seconds since the
    last write, whichever comes first; ``step`` is the step the file holds (None: no file)."""

    def __init__(self, path, every, seconds, held=None):
        self.path, self.every, self.seconds = path, every, seconds
        self.step = held
        self._last = time.monotonic()

    def due(self, step):
        if self.path is None:
            return False
        return (self.every is not None and step % self.every == 0) or (
            self.seconds is not None and time.monotonic() - self._last >= self.seconds)

    def saved(self, step):
        self.step, self._last = step, time.monotonic()


def _check_checkpoint_options(path, every, seconds):
    """The checkpoint's file name, folder and cadence, checked before any work."""
    if path is not None:
        check_output_file(path, ".npz", "checkpoint")
    if every is not None:
        check_positive_int(every, "checkpoint_every")
    if seconds is not None:
        check_positive_float(seconds, "checkpoint_seconds")


def _resume_key(target, options, net):
    """What a checkpoint must match to be resumed: the planned FitOptions' resume key, the
    target and the warm start."""
    keep = options.resume_key()
    keep["smooth"] = getattr(target, "smooth", None)
    keep["target"] = target.fingerprint
    keep["warm_start"] = None if net is None else _fingerprint(net.theta, None)
    return json.dumps(keep, sort_keys=True, default=str)


def _save_checkpoint(path, net, opt, rng_state, step, history, seconds, key, target, metadata,
                     sampler=None):
    surface = SphericalNeuralSurface(net, center=target.center, scale=target.scale,
                                     metadata=dict(metadata or {}))
    arrays = surface.state()
    arrays.update({f"opt.{k}": v for k, v in opt.state_dict().items()})
    arrays.update({
        "checkpoint.step": np.array(step), "checkpoint.seconds": np.array(seconds),
        "checkpoint.key": np.array(key),
        "checkpoint.rng": np.array(json.dumps(rng_state)),
    })
    arrays.update({f"checkpoint.history.{k}": np.asarray(v) for k, v in history.items()})
    if sampler is not None:
        arrays.update({f"checkpoint.sampler.{k}": v for k, v in sampler.state_dict().items()})
    save_npz(path, arrays)


def _load_checkpoint(path, key):
    with load_npz(path) as data:
        if "checkpoint.key" not in data:
            raise ModelFileError(f"{path} is not a fit checkpoint (no checkpoint fields)")
        if str(data["checkpoint.key"]) != key:
            raise ModelFileError(
                f"{path} is a checkpoint of a different fit (other target or options); "
                f"delete it or pass another checkpoint path")
        surface = SphericalNeuralSurface.from_state(data, source=str(path))
        opt = {k[4:]: data[k] for k in data.files if k.startswith("opt.")}
        history = {k[len("checkpoint.history."):]: list(data[k]) for k in data.files
                   if k.startswith("checkpoint.history.")}
        sampler = {k[len("checkpoint.sampler."):]: data[k] for k in data.files
                   if k.startswith("checkpoint.sampler.")}
        return {"net": surface.net, "opt": opt, "step": int(data["checkpoint.step"]),
                "sampler": sampler,
                "seconds": float(data["checkpoint.seconds"]), "history": history,
                "rng": json.loads(str(data["checkpoint.rng"]))}

