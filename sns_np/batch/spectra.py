"""Laplace-Beltrami spectra of many fitted models on a Dask cluster (ShapeDNA)."""

from __future__ import annotations

import os
import socket
import time
import warnings
from pathlib import Path

from .cluster import limit_threads, run_tasks, say, thread_counts
from .fit import _announce, _client, _describe
from .table import Table

__all__ = ["spectra_many"]


def spectrum_columns(k):
    """The columns of a spectra table of ``k`` eigenvalues."""
    return (["name", "status", "message", "seconds", "area", "L", "convergence", "converged"]
            + [f"lambda_{i}" for i in range(1, k + 1)] + ["threads", "worker", "model"])


def _spectrum_one(name, model, k, options, threads):
    """The task: the first k non-zero eigenvalues of one model by Rayleigh-Ritz (a worker)."""
    import json

    from ..spectral import eigenmodes
    from ..surface import SphericalNeuralSurface
    t0 = time.perf_counter()
    row = dict.fromkeys(spectrum_columns(k))
    row.update(name=name, model=str(model), worker=f"{socket.gethostname()}:{os.getpid()}")
    try:
        with limit_threads(threads):
            row["threads"] = json.dumps(thread_counts(), sort_keys=True)
            S = SphericalNeuralSurface.load(model)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", RuntimeWarning)
                res = eigenmodes(S, k, method="ritz", **options)
    except Exception as exc:  # noqa: BLE001 (this model's row fails, the batch goes on)
        text = str(exc).splitlines()[0] if str(exc) else ""
        if not isinstance(exc, (ValueError, OSError)):
            text = f"{type(exc).__name__}: {text}"
        row.update(status="error", message=text, seconds=time.perf_counter() - t0)
        return row
    row.update(status="done", message="; ".join(str(w.message) for w in caught),
               seconds=time.perf_counter() - t0, area=float(res.area), L=int(res.info["L"]),
               convergence=float(res.convergence), converged=bool(res.converged))
    row.update({f"lambda_{i}": float(v) for i, v in enumerate(res.eigenvalues, start=1)})
    return row


def spectra_many(models, k, *, client=None, scheduler=None, workers=None, out=None,
                 threads_per_fit=1, progress=True, **options):
    """The first ``k`` Laplace-Beltrami eigenvalues of every model, on a Dask cluster.

    Each model is one task: :func:`sns_np.spectral.eigenmodes` with ``method="ritz"`` (the
    same solver as ``sns-np eigen``), so the eigenvalues are those of the fitted surface in
    its own units (``Delta phi = -lambda phi``, lambda > 0, the constant mode left out). A
    model that cannot be read or solved fails its own row only.

    Parameters
    ----------
    models : list of path
        Model files (.npz) written by :func:`fit_many` or ``sns-np fit``.
    k : int >= 1
        Number of non-zero eigenvalues per model.
    client, scheduler, workers
        The cluster, as in :func:`fit_many`.
    out : path, optional
        Write the table to ``out`` (.csv) and beside it as JSON (same name, .json).
    threads_per_fit : int
        BLAS and Numba threads of each task (default 1).
    progress : bool
        Progress bar over models and the dashboard address on stderr.
    **options
        Options of :func:`sns_np.spectral.ritz_eigenmodes` (``L``, ``L_max``, ``tol``).

    Returns
    -------
    Table
        One row per model: status, seconds, ``area``, the degree ``L`` and convergence
        indicator of the Ritz basis, ``lambda_1 .. lambda_k``.

    Examples
    --------
    >>> import os, tempfile
    >>> from sns_np.shapes import Sphere
    >>> from sns_np.surface import fit_shape
    >>> S, _ = fit_shape(Sphere(), width=16, depth=1, steps=100, batch=256, n_eval=500,
    ...                  progress=False)
    >>> ball = S.save(os.path.join(tempfile.mkdtemp(), "ball.npz"))
    >>> t = spectra_many([ball], 3, workers=1, progress=False, L=4)
    >>> t[0]["status"], [round(t[0][f"lambda_{i}"]) for i in (1, 2, 3)]  # l(l+1), l = 1
    ('done', [2, 2, 2])
    """
    from .._validation import check_output_file, check_positive_int
    k = check_positive_int(k, "k")
    models = [Path(m) for m in ([models] if isinstance(models, (str, Path)) else models)]
    if not models:
        raise ValueError("no models given")
    threads = check_positive_int(threads_per_fit, "threads_per_fit")
    if out is not None:
        out = check_output_file(out, ".csv", hint=" (the JSON goes beside it)")
    unknown = sorted(set(options) - {"L", "L_max", "tol", "n_theta"})
    if unknown:
        raise TypeError(f"unknown option(s) {', '.join(map(repr, unknown))}; expected some "
                        f"of L, L_max, tol, n_theta")
    t0 = time.perf_counter()
    tasks = [(m.stem, dict(name=m.stem, model=str(m.resolve()), k=k, options=dict(options),
                           threads=threads)) for m in models]

    def error_row(name, kw, message):
        row = dict.fromkeys(spectrum_columns(k))
        row.update(name=name, model=kw["model"], status="error", message=message)
        return row

    with _client(client, scheduler, workers) as c:
        cluster = _describe(c)
        if progress:
            _announce(c, len(tasks), 0, what="spectrum")
        rows = run_tasks(c, _spectrum_one, tasks, label="spectrum", progress=progress,
                         error_row=error_row)
    table = Table(rows, spectrum_columns(k), meta={
        "command": "spectrum", "k": k, "method": "ritz", "options": dict(options),
        "threads_per_fit": threads, "seconds": time.perf_counter() - t0, "cluster": cluster})
    if out is not None:
        table.to_csv(out)
        table.to_json(out.with_suffix(".json"))
        if progress:
            say(f"batch spectrum: wrote {out} and {out.with_suffix('.json')}")
    return table
