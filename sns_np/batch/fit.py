"""Fit many meshes on a Dask cluster: one task per mesh, resumable, each output written once."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import time
from pathlib import Path

from ..options import CHECKPOINT_SECONDS
from .cluster import connect, dashboard_address, limit_threads, run_tasks, say, thread_counts
from .table import Table

__all__ = ["fit_many", "FIT_COLUMNS"]

#: the columns of a fit summary, in order
FIT_COLUMNS = ["name", "status", "message", "seconds", "steps", "stopped", "fit_seconds",
               "position_mean", "position_relative", "normal_mean_deg", "distance_relative",
               "two_sided_distance_relative", "closest_normal_mean_deg", "resumed_from",
               "threads", "worker", "output", "mesh"]

#: options the batch sets itself for every fit
_RESERVED = ("checkpoint", "resume", "progress", "callback", "source", "Vs")
#: options that change when a fit writes checkpoints but not what it computes
_RUNTIME = ("checkpoint_seconds", "checkpoint_every", "history_every")


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _recipe(options, threads):
    """What determines a fitted model besides the mesh: the options given and the threads."""
    keep = {k: v for k, v in options.items() if k not in _RUNTIME and v is not None}
    keep["threads_per_fit"] = int(threads)
    return json.loads(json.dumps(keep, sort_keys=True, default=str))


def _fit_figures(metadata):
    fit = metadata.get("fit") or {}
    return {"steps": fit.get("steps"), "stopped": fit.get("stopped"),
            "fit_seconds": fit.get("seconds"), "position_mean": fit.get("position_mean"),
            "position_relative": fit.get("position_relative"),
            "normal_mean_deg": fit.get("normal_mean_deg"),
            "distance_relative": fit.get("distance_relative"),
            "two_sided_distance_relative": fit.get("two_sided_distance_relative"),
            "closest_normal_mean_deg": fit.get("closest_normal_mean_deg")}


def _completed(out, recipe, mesh_sha):
    """Whether ``out`` holds this fit already: None (absent), True, or the reason it does not
    match (a str naming the difference)."""
    from ..errors import ModelFileError
    from ..surface import SphericalNeuralSurface
    if not os.path.exists(out):
        return None
    try:
        S = SphericalNeuralSurface.load(out)
    except (ModelFileError, OSError, ValueError) as exc:
        return f"it is not a readable model ({str(exc).splitlines()[0]})"
    batch = S.metadata.get("batch")
    if not isinstance(batch, dict):
        return "it was not written by a batch fit (no batch record in its metadata)"
    old = batch.get("recipe", {})
    if old != recipe:
        keys = sorted(set(old) | set(recipe))
        diff = [f"{k} {old.get(k)!r} -> {recipe.get(k)!r}" for k in keys
                if old.get(k) != recipe.get(k)]
        return f"it was fitted with other options ({'; '.join(diff)})"
    if batch.get("mesh_sha256") != mesh_sha:
        return "it was fitted to another version of the mesh file (its SHA-256 differs)"
    return S


def _checkpoint_step(path):
    """The step a checkpoint holds, or None when there is none (or it cannot be read)."""
    import numpy as np
    if not os.path.exists(path):
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            return int(data["checkpoint.step"])
    except Exception:  # noqa: BLE001 (a damaged checkpoint: the fit itself will say so)
        return None


def _row(name, mesh, out, status, message="", **figures):
    row = dict.fromkeys(FIT_COLUMNS)
    row.update(name=name, mesh=str(mesh), output=str(out), status=status, message=message)
    row.update(figures)
    return row


def _fit_one(name, mesh, out, checkpoint, options, recipe, threads, keep_checkpoint):
    """The task that fits one mesh (runs on a worker); returns its row, never raises for a
    problem of this shape (bad mesh, divergence, output in use)."""
    from .._atomic import exclusive, remove_stale_temporaries
    from ..mesh import check, load
    from ..surface import fit_mesh
    t0 = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    out, checkpoint = Path(out), Path(checkpoint)
    try:
        with limit_threads(threads), exclusive(out):
            remove_stale_temporaries(out)
            mesh_sha = _sha256(mesh)
            done = _completed(out, recipe, mesh_sha)
            if done is not None and not isinstance(done, str):
                # written by an earlier attempt of this task whose worker then died
                if not keep_checkpoint:
                    checkpoint.unlink(missing_ok=True)
                return _row(name, mesh, out, "skipped", "complete already", worker=worker,
                            seconds=time.perf_counter() - t0, **_fit_figures(done.metadata))
            if isinstance(done, str):
                raise ValueError(f"{out} exists and {done}; remove it or choose another "
                                 f"output folder")
            resumed_from = _checkpoint_step(checkpoint)
            V, F = load(mesh)
            check(V, F)                          # the one-line message of a bad mesh
            threads_seen = thread_counts()
            S, report = fit_mesh(V, F, checkpoint=checkpoint, resume=True, check=False,
                                 progress=False, source=str(mesh), **options)
            S.metadata["batch"] = {"recipe": recipe, "mesh_sha256": mesh_sha,
                                   "resumed_from": resumed_from, "threads": threads_seen,
                                   "worker": worker}
            S.save(out)
            if not keep_checkpoint:
                checkpoint.unlink(missing_ok=True)
    except Exception as exc:  # noqa: BLE001 (this shape's row fails, the batch goes on)
        text = str(exc).splitlines()[0] if str(exc) else ""
        if not isinstance(exc, (ValueError, OSError)):
            text = f"{type(exc).__name__}: {text}"
        return _row(name, mesh, out, "error", text, worker=worker,
                    seconds=time.perf_counter() - t0)
    return _row(name, mesh, out, "done", "", worker=worker, resumed_from=resumed_from,
                threads=json.dumps(threads_seen, sort_keys=True),
                seconds=time.perf_counter() - t0, **_fit_figures(S.metadata))


def _check_names(meshes):
    """One output name per mesh: the file stem, unique (case-insensitively) in the batch."""
    names = {}
    for m in meshes:
        stem = Path(m).stem
        if stem.lower().endswith(".ckpt"):
            raise ValueError(f"mesh {str(m)!r}: a name ending in '.ckpt' would collide with "
                             f"the checkpoints; rename the file")
        if stem.lower() == "summary":
            continue                        # summary.npz does not collide with summary.csv
        names.setdefault(stem.lower(), []).append(str(m))
    clash = {k: v for k, v in names.items() if len(v) > 1}
    if clash:
        k, v = next(iter(clash.items()))
        raise ValueError(f"{len(v)} meshes would write the same output {Path(v[0]).stem}.npz: "
                         f"{', '.join(v)}" + (f" (and {len(clash) - 1} more clashes)"
                                              if len(clash) > 1 else "")
                         + "; rename them or run them in separate batches")


def fit_many(meshes, out_dir, *, client=None, scheduler=None, workers=None, threads_per_fit=1,
             checkpoint_dir=None, checkpoint_seconds=CHECKPOINT_SECONDS, keep_checkpoint=False,
             progress=True, **fit_options):
    """Fit every mesh on a Dask cluster; one ``NAME.npz`` per mesh and a summary in out_dir.

    Every mesh is one task: :func:`sns_np.mesh.check`, then :func:`sns_np.surface.fit_mesh`
    with a checkpoint ``NAME.ckpt.npz`` (written every ``checkpoint_seconds`` and resumed when
    present), then the model saved atomically. A bad mesh fails its own row only. A task whose
    worker is killed is rescheduled by Dask and resumes from the checkpoint. Outputs that are
    complete (same options, same mesh file) are skipped, so rerunning a batch only does what
    is left; an output fitted with other options is refused before any work starts.

    Parameters
    ----------
    meshes : list of path
        Mesh files (.obj, .off, .ply, .stl); their stems name the outputs and must differ.
        Workers read them (and write out_dir): on a cluster of several machines the paths
        must be on a shared file system.
    out_dir : path
        Output folder, created if absent (its parent must exist).
    client : distributed.Client, optional
        Run on this client's cluster (it is left open). Default: ``scheduler`` if given,
        else a local cluster of processes (:func:`connect`), closed at the end.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:port``).
    workers : int, optional
        Worker processes of the local cluster (default: one per core).
    threads_per_fit : int
        BLAS and Numba threads of each fit (default 1, each worker's share on the local
        cluster). The model of a mesh is bit-for-bit the same on every worker at a given
        value (docs/batch.md); it is part of what a completed output must match.
    checkpoint_dir : path, optional
        Folder of the checkpoints (default: out_dir).
    checkpoint_seconds : float
        Checkpoint cadence of each fit: a killed worker costs at most this much of its fit.
    keep_checkpoint : bool
        Keep ``NAME.ckpt.npz`` after the model is saved.
    progress : bool
        A progress bar over shapes on stderr, and the dashboard address.
    **fit_options
        Options of :func:`sns_np.surface.fit_mesh`: the fields of
        :class:`~sns_np.surface.FitOptions` (steps, time_budget, width, depth, ...),
        ``smooth`` and ``creases``.

    Returns
    -------
    Table
        One row per mesh, in the order given (:data:`FIT_COLUMNS`): status ``done``,
        ``skipped`` (complete already) or ``error`` (with the one-line message), seconds of
        the task, the fit's figures, the output path. Also written as ``summary.csv`` and
        ``summary.json`` in out_dir.

    Examples
    --------
    >>> import os, tempfile
    >>> from sns_np.mesh import write_mesh
    >>> from sns_np.shapes import Ellipsoid
    >>> d = tempfile.mkdtemp()
    >>> _ = write_mesh(os.path.join(d, "egg.obj"), *Ellipsoid(1.0, 1.3, 0.7).mesh(1))
    >>> with open(os.path.join(d, "open.obj"), "w") as fh:   # one triangle: not closed
    ...     _ = fh.write("v 0 0 0\\nv 1 0 0\\nv 0 1 0\\nf 1 2 3\\n")
    >>> t = fit_many([os.path.join(d, "egg.obj"), os.path.join(d, "open.obj")],
    ...              os.path.join(d, "out"), workers=1, progress=False,
    ...              width=8, depth=1, steps=5, batch=64, n_eval=100)
    >>> t.column("status"), t[0]["steps"]
    (['done', 'error'], 5)
    >>> sorted(os.listdir(os.path.join(d, "out")))
    ['egg.npz', 'summary.csv', 'summary.json']
    """
    meshes = [Path(m) for m in ([meshes] if isinstance(meshes, (str, Path)) else meshes)]
    if not meshes:
        raise ValueError("no meshes given")
    _check_names(meshes)
    reserved = sorted(set(fit_options) & set(_RESERVED))
    if reserved:
        raise TypeError(f"fit_many sets {', '.join(reserved)} itself for every fit")
    from ..options import MESH_SMOOTHING, FitOptions, check_smooth
    # unknown names and bad values are refused here, before the cluster starts
    FitOptions.split(fit_options, extra=_RUNTIME + ("smooth", "creases"))
    check_smooth(fit_options.get("smooth") or MESH_SMOOTHING[0],
                 fit_options.get("creases") or "auto")
    threads = int(threads_per_fit)
    if threads < 1:
        raise ValueError(f"threads_per_fit must be >= 1, got {threads_per_fit}")
    # folders are checked now and created once the cluster is reached (a batch that cannot
    # start leaves nothing behind)
    out_dir = _check_folder(out_dir, "output")
    ck_dir = out_dir if checkpoint_dir is None else _check_folder(checkpoint_dir, "checkpoint")
    fit_options = {k: v for k, v in fit_options.items() if v is not None}
    fit_options["checkpoint_seconds"] = checkpoint_seconds
    recipe = _recipe(fit_options, threads)

    t0 = time.perf_counter()
    rows, tasks = [None] * len(meshes), []
    for i, m in enumerate(meshes):
        name, out = m.stem, out_dir / f"{m.stem}.npz"
        sha = _sha256(m) if m.is_file() else None
        done = _completed(out, recipe, sha) if sha else None
        if isinstance(done, str):
            raise ValueError(f"{out} exists and {done}; remove it or choose another output "
                             f"folder")
        if done is not None:
            rows[i] = _row(name, m.resolve(), out, "skipped", "complete already", seconds=0.0,
                           **_fit_figures(done.metadata))
            continue
        tasks.append((i, dict(name=name, mesh=str(m.resolve()), out=str(out.resolve()),
                              checkpoint=str((ck_dir / f"{name}.ckpt.npz").resolve()),
                              options=fit_options, recipe=recipe, threads=threads,
                              keep_checkpoint=bool(keep_checkpoint))))
    cluster = {}
    if tasks:
        with _client(client, scheduler, workers) as c:
            out_dir.mkdir(exist_ok=True)
            ck_dir.mkdir(exist_ok=True)
            cluster = _describe(c)
            if progress:
                _announce(c, len(tasks), len(meshes) - len(tasks))
            done_rows = run_tasks(
                c, _fit_one, [(kw["name"], kw) for _, kw in tasks], label="fit",
                progress=progress,
                error_row=lambda name, kw, msg: _row(name, kw["mesh"], kw["out"], "error",
                                                     msg))
        for (i, _), row in zip(tasks, done_rows):
            rows[i] = row
    elif progress:
        say(f"batch fit: all {len(meshes)} outputs are complete already; nothing to do")
    table = Table(rows, FIT_COLUMNS, meta={
        "command": "fit", "options": recipe, "out_dir": str(out_dir.resolve()),
        "seconds": time.perf_counter() - t0, "cluster": cluster,
        "counts": {s: sum(r["status"] == s for r in rows) for s in ("done", "skipped", "error")},
    })
    out_dir.mkdir(exist_ok=True)
    table.to_csv(out_dir / "summary.csv")
    table.to_json(out_dir / "summary.json")
    return table


def _check_folder(path, what):
    """A folder that exists and is writable, or whose parent does (it is made later)."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.exists() and not path.is_dir():
        raise ValueError(f"{what} folder {str(path)!r} exists and is not a folder")
    if not path.exists() and not parent.is_dir():
        raise ValueError(f"parent folder {str(parent)!r} of the {what} folder does not exist")
    here = path if path.exists() else parent
    if not os.access(here, os.W_OK | os.X_OK):
        raise ValueError(f"{what} folder {str(here)!r} is not writable")
    return path


@contextlib.contextmanager
def _client(client, scheduler, workers):
    """The caller's client as it is, or one made by :func:`connect` (closed afterwards)."""
    if client is not None:
        if scheduler is not None or workers is not None:
            raise ValueError("pass either client, or scheduler / workers, not both")
        yield client
        return
    with connect(scheduler, workers=workers) as c:
        yield c


def _describe(client):
    """The cluster in a few JSON-friendly facts (for the summary)."""
    try:
        info = client.scheduler_info()
        ws = info.get("workers", {})
        return {"scheduler": info.get("address"), "workers": len(ws),
                "threads": sum(w.get("nthreads", 0) for w in ws.values()),
                "dashboard": dashboard_address(client)}
    except Exception:  # noqa: BLE001 (a description only)
        return {}


def _announce(client, n_tasks, n_skipped, what="fit"):
    d = _describe(client)
    say(f"batch {what}: {n_tasks} tasks on {d.get('workers')} workers ({d.get('threads')} "
        f"threads) at {d.get('scheduler')}" + (f"; {n_skipped} complete already, skipped"
                                               if n_skipped else ""))
    link = d.get("dashboard")
    if link:
        say(f"dashboard: {link}")
