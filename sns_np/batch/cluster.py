"""The Dask side of a batch: the client, the local cluster's layout, thread limits, and running
one task per shape with a progress bar.

Dask (``dask.distributed``) is an optional extra, imported inside the functions that need it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import sys
import threading
import uuid

from .._progress import Progress

__all__ = ["connect", "local_layout", "limit_threads", "dashboard_address"]

EXTRA = 'pip install "sns-np[distributed]"'


def _require():
    """Import dask.distributed, or say which extra installs it."""
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(f"sns_np.batch needs the optional extra 'distributed' ({exc}); "
                          f"install it with: {EXTRA}") from None
    return distributed


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                                  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def local_layout(workers=None, cores=None):
    """Worker processes and threads per process of a local cluster: their product is the cores.

    Parameters
    ----------
    workers : int, optional
        Worker processes (default: one per core, each with one thread).
    cores : int, optional
        Cores to fill (default: those this process may run on).

    Returns
    -------
    (processes, threads) : tuple of int
        With more processes than cores each still gets one thread (oversubscribed).

    Examples
    --------
    >>> local_layout(cores=8), local_layout(2, cores=8), local_layout(3, cores=8)
    ((8, 1), (2, 4), (3, 2))
    """
    cores = _cores() if cores is None else int(cores)
    if workers is None:
        return cores, 1
    workers = int(workers)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    return workers, max(1, cores // workers)


@contextlib.contextmanager
def connect(scheduler=None, *, workers=None):
    """A ``dask.distributed.Client``: to a running scheduler, or to a new local cluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:port``, e.g. one started with
        ``dask scheduler``). Default: start a local cluster of worker processes, laid out by
        :func:`local_layout` (processes x threads = cores), on 127.0.0.1 only, and close it on
        exit.
    workers : int, optional
        Worker processes of the local cluster (not allowed with ``scheduler``).

    Yields
    ------
    distributed.Client

    Examples
    --------
    >>> with connect(workers=1) as client:         # one worker process, all the cores
    ...     client.submit(sum, [1, 2]).result()
    3
    >>> try:
    ...     with connect("tcp://127.0.0.1:1", workers=2):
    ...         pass
    ... except ValueError as exc:
    ...     print(exc)
    workers applies to a local cluster; a running scheduler has its own workers
    """
    if scheduler is not None:
        if workers is not None:
            raise ValueError("workers applies to a local cluster; a running scheduler has its "
                             "own workers")
        distributed = _require()
        try:
            client = distributed.Client(str(scheduler), timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise OSError(f"cannot reach the Dask scheduler at {scheduler!r} "
                          f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
                          ) from None
        try:
            yield client
        finally:
            client.close()
        return
    distributed = _require()
    n, threads = local_layout(workers)
    # the dashboard on a free port (":8787" may be taken by another cluster on the machine)
    cluster = distributed.LocalCluster(
        n_workers=n, threads_per_worker=threads, processes=True, host="127.0.0.1",
        dashboard_address=":0", silence_logs=logging.ERROR)
    try:
        client = distributed.Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def dashboard_address(client):
    """The client's dashboard URL, or None when the scheduler runs none.

    Without bokeh here the URL carries a note: the scheduler's status pages need it.

    Examples
    --------
    >>> class NoDashboard:                  # any object with scheduler_info() will do
    ...     def scheduler_info(self):
    ...         return {"services": {}}
    >>> dashboard_address(NoDashboard()) is None
    True
    """
    try:
        services = client.scheduler_info().get("services", {})
    except Exception:  # noqa: BLE001 (a closed client: no dashboard to show)
        return None
    if "dashboard" not in services:
        return None
    link = client.dashboard_link
    if importlib.util.find_spec("bokeh") is None:
        link += " (its status pages need bokeh >= 3.1: pip install bokeh)"
    return link


# ------------------------------------------------------------------------------ thread limits

_limit = {"lock": threading.Lock(), "count": 0, "limiter": None, "n": None}


@contextlib.contextmanager
def limit_threads(n):
    """Run the body with ``n`` BLAS threads (every BLAS of the process) and ``n`` Numba threads.

    BLAS limits are per process (threadpoolctl): while several tasks of one worker process
    are inside, the first one's limit holds, and the previous limits come back when the last
    one leaves. Numba's count is per thread. The engine sizes its data-parallel sections from
    the BLAS thread count, and the order in which it adds partial gradients depends on it, so a
    fit is bit-for-bit reproducible only at a fixed ``n`` (docs/batch.md).

    Examples
    --------
    >>> import numba
    >>> with limit_threads(1):
    ...     numba.get_num_threads()
    1
    """
    import numba
    from threadpoolctl import threadpool_limits

    n = int(n)
    if n < 1:
        raise ValueError(f"threads must be >= 1, got {n}")
    st = _limit
    with st["lock"]:
        if st["count"] == 0:
            st["limiter"], st["n"] = threadpool_limits(limits=n), n
        st["count"] += 1
    before = numba.get_num_threads()
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    try:
        yield
    finally:
        numba.set_num_threads(before)
        with st["lock"]:
            st["count"] -= 1
            if st["count"] == 0:
                st["limiter"].restore_original_limits()
                st["limiter"] = st["n"] = None


def thread_counts() -> dict:
    """The BLAS and Numba thread counts in force here (what a task records in its row)."""
    import numba
    from threadpoolctl import threadpool_info
    blas = sorted({d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"})
    return {"blas": blas[0] if len(blas) == 1 else blas, "numba": numba.get_num_threads()}


# ------------------------------------------------------------------------------ running tasks

def run_tasks(client, fn, tasks, *, label, progress, error_row, stream=None):
    """``fn(**task)`` for every task on the cluster; the rows in task order.

    ``tasks`` is a list of ``(name, kwargs)``. A task that raises, or whose worker died too
    often (``KilledWorker``), becomes ``error_row(name, kwargs, message)``; the others go on.
    A progress bar counts finished shapes. Ctrl-C cancels what has not finished.
    """
    distributed = _require()
    token = uuid.uuid4().hex[:8]
    futures = {}
    for i, (name, kwargs) in enumerate(tasks):
        f = client.submit(fn, pure=False, key=f"sns-np-{label}-{name}-{token}-{i}", **kwargs)
        futures[f] = i
    rows = [None] * len(tasks)
    bar = Progress(len(tasks), f"batch {label}", enabled=progress, stream=stream)
    done = failed = 0
    try:
        for f in distributed.as_completed(list(futures)):
            i = futures[f]
            name, kwargs = tasks[i]
            if f.status == "finished":
                rows[i] = f.result()
            else:
                exc = f.exception()
                text = str(exc).splitlines()[0] if str(exc) else ""
                rows[i] = error_row(name, kwargs, f"{type(exc).__name__}: {text}".rstrip(": "))
            failed += rows[i].get("status") == "error"
            done += 1
            bar.update(done, force=True, last=name, failed=failed)
    except BaseException:
        client.cancel(list(futures))
        raise
    finally:
        bar.close()
    return rows


def say(message, stream=None):
    """One line on stderr (where the progress bar is), flushed."""
    stream = stream or sys.stderr
    stream.write(message + "\n")
    stream.flush()
