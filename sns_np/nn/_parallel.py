"""Data-parallel execution of the engine over point chunks (private).

Why
---
A jet of a wide network alternates BLAS products with fused Numba passes: 2 x depth of each per
chunk. Run the obvious way (every product on all of OpenBLAS's threads, every pass on all of
Numba's), the two thread pools hand the cores over to each other at every alternation: on
2 cores, 320 hand-overs per 4096-point jet cost about 0.1 s of 1 s (docs/performance.md).
Nothing in a jet couples two points, so the engine instead gives each worker thread whole
chunks: every worker runs single-threaded products and serial, GIL-free Numba passes on its
own chunk, back to back, with no hand-over at all, and its operands stay in its own core's
cache.

How
---
* BLAS threads are controlled through threadpoolctl: one ``ThreadpoolController``, created
  on first use, finds the BLAS libraries loaded in the process (OpenBLAS, MKL, BLIS, ...).
* The worker count is the thread count of NumPy's BLAS when the call starts: it follows
  ``OPENBLAS_NUM_THREADS`` and any runtime limit the caller set (``threadpool_limits``, say).
* For the duration of the call every BLAS is limited to one thread
  (``ThreadpoolController.limit``, 0.03 ms a call against 100 ms and more of work), then
  restored. A lock keeps two parallel sections from interleaving those settings; code running
  inside a worker (a loss function calling the network, say) runs serially and never waits for
  that lock.
* Where NumPy's BLAS cannot be controlled (Accelerate), or it has one thread, :func:`plan`
  returns ``None`` and the engine keeps its threaded-BLAS path.

The calling thread is one of the workers; the others live in a pool created on first use and
re-created after ``fork``.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor


class _Blas:
    """The thread count of one BLAS library (a threadpoolctl library controller)."""

    def __init__(self, controller):
        self.controller = controller
        self.path = controller.filepath

    def get(self) -> int:
        return int(self.controller.num_threads)

    def set(self, n: int) -> None:
        self.controller.set_num_threads(int(n))


def _numpy_blas_first(libs):
    """The BLAS libraries with NumPy's first (its thread count sets the number of workers);
    none when NumPy's BLAS is not among them (only then may the others be trusted).

    NumPy >= 1.26 names its BLAS in its build configuration; older ones are recognised by a
    library inside NumPy's own installation (a wheel's ``numpy.libs``).
    """
    import numpy

    try:
        name = str(numpy.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"])
    except Exception:  # noqa: BLE001 (NumPy < 1.26, or a layout we do not know)
        name = ""
    ours = [lib for lib in libs if "numpy" in lib.path
            or (name and lib.controller.internal_api in name.lower())]
    if not ours:
        return []
    ours.sort(key=lambda lib: "numpy" not in lib.path)
    return ours + [lib for lib in libs if lib not in ours]


_lock = threading.Lock()
_local = threading.local()
_state = {"controller": None, "blas": None, "pool": None, "pool_size": 0}
_enabled = os.environ.get("SNS_NP_DATA_PARALLEL", "1") != "0"


def _controller():
    """The process's threadpoolctl controller of the BLAS libraries (created once, lazily)."""
    if _state["controller"] is None:
        import numpy  # noqa: F401  (loads NumPy's BLAS, if it has not been loaded yet)
        from threadpoolctl import ThreadpoolController

        _state["controller"] = ThreadpoolController().select(user_api="blas")
    return _state["controller"]


def _blas():
    """The controllable BLAS libraries, NumPy's first; [] when NumPy's is not one of them."""
    if _state["blas"] is None:
        _state["blas"] = _numpy_blas_first([_Blas(c) for c in _controller().lib_controllers])
    return _state["blas"]


def _reset_after_fork():
    """A forked child has none of the parent's threads: a new pool, and a free lock (a fork
    in the middle of a parallel section would otherwise leave it held forever)."""
    global _lock
    _state["pool"], _state["pool_size"] = None, 0
    _lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reset_after_fork)


def inside_worker() -> bool:
    """True in a worker of a running parallel section (nested calls then run serially)."""
    return getattr(_local, "active", False)


def plan(n: int, c: int):
    """How to run n points in chunks of at most c: ``(workers, chunk)``, or None.

    None means the threaded path (threaded BLAS and threaded passes, chunk after chunk).
    Otherwise the chunk is shrunk so that every worker gets the same number of equal chunks
    (a worker left with one chunk more than the others would make the rest wait); one worker
    means a serial run in the calling thread (serial kernels, BLAS untouched), which is also
    what a nested call inside a worker gets.
    """
    c = max(1, min(c, n))
    if inside_worker():
        return 1, c
    if not _enabled:
        return None
    libs = _blas()
    if not libs:
        return None
    workers = max(1, min(libs[0].get(), -(-n // c)))
    return workers, balanced_chunk(n, c, workers)


def balanced_chunk(n: int, c: int, workers: int) -> int:
    """The largest chunk <= c that splits n points into ``workers x rounds`` nearly equal ones."""
    rounds = -(-n // (workers * c))
    return -(-n // (workers * rounds))


def _pool(size):
    if _state["pool_size"] < size:
        if _state["pool"] is not None:
            _state["pool"].shutdown(wait=True)
        _state["pool"] = ThreadPoolExecutor(max_workers=size, thread_name_prefix="sns_np")
        _state["pool_size"] = size
    return _state["pool"]


def shutdown():
    """End the worker threads (a new pool is started when next needed); waits for a running
    parallel section to finish first."""
    with _lock:
        if _state["pool"] is not None:
            _state["pool"].shutdown(wait=True)
        _state["pool"], _state["pool_size"] = None, 0


def _as_worker(fn, *args):
    before = inside_worker()
    _local.active = True
    try:
        return fn(*args)
    finally:
        _local.active = before


def run(work, n_workers: int, queue: TaskQueue | None = None):
    """Call ``work(i)`` for i in range(n_workers), concurrently; the results in order.

    With n_workers == 1 it is a plain call in this thread. Otherwise every BLAS runs
    single-threaded until all workers have finished. When one raises (or the caller is
    interrupted), ``queue`` is closed so that the others stop after their current task, and
    the first exception is re-raised once they are done.
    """
    if n_workers <= 1:
        return [_as_worker(work, 0)]
    with _lock, _controller().limit(limits=1, user_api="blas"):
        pool = _pool(n_workers - 1)
        futures = [pool.submit(_as_worker, work, i) for i in range(1, n_workers)]
        results, errors = [None] * n_workers, []
        for i in range(n_workers):
            try:
                results[i] = _as_worker(work, 0) if i == 0 else futures[i - 1].result()
            except BaseException as exc:  # noqa: BLE001 (re-raised below, after the workers)
                errors.append(exc)
                if queue is not None:
                    queue.close()
        if errors:
            raise errors[0]
        return results


def for_each(fn, n: int) -> None:
    """Call ``fn(i)`` for i in range(n), spread over the workers as whole tasks (each worker
    with single-threaded BLAS, as in a jet), or one after the other in this thread when there
    is no parallel plan. Used for independent work on many small matrices (the optimiser
    SOAP), whose threaded products would leave OpenBLAS's threads spinning into the next jet.
    """
    p = plan(n, 1)
    if p is None or p[0] <= 1:
        for i in range(n):
            fn(i)
        return
    queue = TaskQueue(n)

    def work(_):
        for i in queue:
            fn(i)

    run(work, p[0], queue)


class TaskQueue:
    """Hands out 0, 1, ..., n - 1 to whichever worker asks next (thread-safe)."""

    def __init__(self, n: int):
        self._n = n
        self._next = 0
        self._lock = threading.Lock()
        self.closed = False

    def __iter__(self):
        while True:
            with self._lock:
                if self.closed or self._next >= self._n:
                    return
                i = self._next
                self._next += 1
            yield i

    def close(self):
        """Stop handing out tasks (a worker failed: the others finish their current task)."""
        self.closed = True
