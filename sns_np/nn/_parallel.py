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
* The worker count is OpenBLAS's thread count when the call starts: it follows
  ``OPENBLAS_NUM_THREADS`` and any runtime limit the caller set (threadpoolctl, say).
* For the duration of the call every OpenBLAS loaded in the process is set to one thread (by
  its ``*_set_num_threads`` entry point, found with ctypes), then restored. A lock keeps two
  parallel sections from interleaving those settings; code running inside a worker (a loss
  function calling the network, say) runs serially and never waits for that lock.
* Where no OpenBLAS can be found (Accelerate, MKL, a BLAS without that entry point), or it
  has one thread, :func:`plan` returns ``None`` and the engine keeps its threaded-BLAS path.

The calling thread is one of the workers; the others live in a pool created on first use and
re-created after ``fork``.
"""

from __future__ import annotations

import ctypes
import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

_SET_NAMES = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
              "openblas_set_num_threads64_", "openblas_set_num_threads")


class _OpenBLAS:
    """Get/set the thread count of one loaded OpenBLAS through its C entry points."""

    def __init__(self, lib, set_name):
        self.path = lib._name
        self._set = getattr(lib, set_name)
        self._set.argtypes = [ctypes.c_int]
        self._set.restype = None
        self._get = getattr(lib, set_name.replace("set_num", "get_num"))
        self._get.argtypes = []
        self._get.restype = ctypes.c_int

    def get(self) -> int:
        return int(self._get())

    def set(self, n: int) -> None:
        self._set(int(n))


def _loaded_openblas_paths():
    """Shared libraries of this process whose file name contains 'openblas' (Linux only)."""
    try:
        with open("/proc/self/maps") as f:
            lines = f.read().splitlines()
    except OSError:
        return []
    paths = []
    for line in lines:
        parts = line.split(None, 5)
        if len(parts) == 6 and "openblas" in os.path.basename(parts[5]).lower():
            path = parts[5].strip()
            if path not in paths and os.path.exists(path):
                paths.append(path)
    return paths


def _numpy_blas_is_openblas(found):
    """Whether NumPy's products run on an OpenBLAS (only then may it be controlled).

    NumPy >= 1.26 names its BLAS in its build configuration; older ones are trusted only when
    an OpenBLAS lies inside NumPy's own installation (a wheel's ``numpy.libs``).
    """
    import numpy

    try:
        name = numpy.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"]
    except Exception:  # noqa: BLE001 (NumPy < 1.26, or a layout we do not know)
        return any("numpy" in lib.path for lib in found)
    return "openblas" in str(name).lower()


def _find_openblas():
    import numpy  # noqa: F401  (loads NumPy's BLAS, if it has not been loaded yet)

    found = []
    for path in _loaded_openblas_paths():
        try:
            lib = ctypes.CDLL(path)  # already loaded: returns the loaded copy
        except OSError:
            continue
        for name in _SET_NAMES:
            if hasattr(lib, name) and hasattr(lib, name.replace("set_num", "get_num")):
                found.append(_OpenBLAS(lib, name))
                break
    if not _numpy_blas_is_openblas(found):
        return []  # MKL, Accelerate, ...: an OpenBLAS of SciPy's would be the wrong one
    # NumPy's own first: its thread count decides the number of workers
    found.sort(key=lambda lib: "numpy" not in lib.path)
    return found


_lock = threading.Lock()
_local = threading.local()
_state = {"blas": None, "pool": None, "pool_size": 0}
_enabled = os.environ.get("SNS_NP_DATA_PARALLEL", "1") != "0"


def _blas():
    if _state["blas"] is None:
        _state["blas"] = _find_openblas() if sys.platform.startswith("linux") else []
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


@contextmanager
def _single_threaded_blas():
    libs = _blas()
    before = [lib.get() for lib in libs]
    for lib in libs:
        lib.set(1)
    try:
        yield
    finally:
        for lib, n in zip(libs, before):
            lib.set(n)


def _as_worker(fn, *args):
    before = inside_worker()
    _local.active = True
    try:
        return fn(*args)
    finally:
        _local.active = before


def run(work, n_workers: int, queue: TaskQueue | None = None):
    """Call ``work(i)`` for i in range(n_workers), concurrently; the results in order.

    With n_workers == 1 it is a plain call in this thread. Otherwise every OpenBLAS runs
    single-threaded until all workers have finished. When one raises (or the caller is
    interrupted), ``queue`` is closed so that the others stop after their current task, and
    the first exception is re-raised once they are done.
    """
    if n_workers <= 1:
        return [_as_worker(work, 0)]
    with _lock, _single_threaded_blas():
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
