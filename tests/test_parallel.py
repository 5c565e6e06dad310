"""Data-parallel engine runs (sns_np.nn._parallel): the same numbers as the threaded path,
deterministic gradients, nested calls, errors from workers, OpenBLAS settings restored."""

import numpy as np
import pytest

from sns_np.nn import ResidualMLP, _engine, _parallel, release_workspace
from sns_np.nn import _kernels as K

needs_openblas = pytest.mark.skipif(not _parallel._blas(),
                                    reason="no OpenBLAS whose thread count can be set")


@pytest.fixture
def two_workers():
    """At least two BLAS threads (hence two workers) for the test, restored afterwards."""
    libs = _parallel._blas()
    before = [lib.get() for lib in libs]
    for lib in libs:
        lib.set(max(2, lib.get()))
    if libs[0].get() < 2:
        pytest.skip("OpenBLAS runs one thread here: no second worker")
    yield
    for lib, n in zip(libs, before):
        lib.set(n)


def make_net(bias=True, dtype=np.float64, chunk_size=37):
    net = ResidualMLP(width=64, depth=2, bias=bias, seed=3, dtype=dtype, chunk_size=chunk_size)
    g = np.random.default_rng(4)
    net.W3[...] = g.standard_normal(net.W3.shape) / 8
    for b in ("b0", "b1", "b2", "b3"):
        getattr(net, b)[...] = 0.3 * g.standard_normal(getattr(net, b).shape)
    return net


def points(n, seed=0):
    x = np.random.default_rng(seed).standard_normal((n, 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


@pytest.mark.parametrize("n, c, workers", [(4096, 102, 2), (2048, 341, 2), (10, 3, 2),
                                           (7, 100, 2), (1000, 1, 3), (999, 64, 4), (5, 5, 1)])
def test_balanced_chunks_share_the_points_equally(n, c, workers):
    chunk = _parallel.balanced_chunk(n, c, workers)
    assert 1 <= chunk <= c
    n_chunks = -(-n // chunk)
    sizes = [min(chunk, n - i * chunk) for i in range(n_chunks)]
    loads = [sum(sizes[w::workers]) for w in range(workers)]
    rounds = -(-n // (workers * c))
    assert sum(loads) == n
    assert max(loads) <= n / workers + rounds  # never one whole chunk more than the others


def test_serial_and_threaded_kernels_agree_bitwise():
    g = np.random.default_rng(5)
    c, m, k, w = 9, 3, 3, 40
    S = 1 + m + k * (k + 1) // 2
    Z, R = g.standard_normal((2, c, S, w)) * 3
    bias = g.standard_normal(w)
    outs = []
    for kernel in (K.softplus_jet, K.softplus_jet_serial):
        Zc, out, sig = Z.copy(), np.empty_like(Z), np.empty((c, w))
        kernel(Zc, R, bias, out, sig, m, k, True, True)
        outs.append((Zc, out, sig))
    for a, b in zip(*outs):
        assert np.array_equal(a, b)
    A = g.standard_normal((c, 1 + m, w))
    back = []
    for kernel in (K.softplus_jet_back, K.softplus_jet_back_serial):
        out = np.empty_like(A)
        kernel(Z[:, :1 + m].copy(), outs[0][2], A, out, m)
        back.append(out)
    assert np.array_equal(back[0], back[1])


@needs_openblas
@pytest.mark.parametrize("dtype, rtol", [(np.float64, 1e-13), (np.float32, 1e-5)])
def test_data_parallel_jets_match_the_threaded_path(two_workers, monkeypatch, dtype, rtol):
    net = make_net(dtype=dtype)
    x = points(1001)
    D = np.random.default_rng(1).standard_normal((1001, 3, 3))
    assert _parallel.plan(1001, 37)[0] >= 2
    par = [net.jet(x, 2), net.jet(x, 2, directions=D, second=2), net.jet(x, 0)]
    monkeypatch.setattr(_parallel, "_enabled", False)
    assert _parallel.plan(1001, 37) is None
    ref = [net.jet(x, 2), net.jet(x, 2, directions=D, second=2), net.jet(x, 0)]
    for a, b in zip(par, ref):
        for u, v in zip(a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,)):
            np.testing.assert_allclose(u, v, rtol=rtol, atol=rtol * np.abs(v).max())


def _loss(q):
    def loss(y, JD, sl):
        r = y - q[sl]
        return float(np.sum(r * r)), 2 * r, 0.1 * JD
    return loss


@needs_openblas
def test_data_parallel_gradient_is_deterministic_and_matches(two_workers, monkeypatch):
    net = make_net()
    x = points(777)
    q = 1.3 * x
    D = np.random.default_rng(2).standard_normal((777, 3, 2))
    assert _parallel.plan(777, 37)[0] >= 2
    l1, g1 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    l2, g2 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    assert l1 == l2 and np.array_equal(g1, g2)  # round-robin chunks: no dependence on timing
    monkeypatch.setattr(_parallel, "_enabled", False)
    l3, g3 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    assert l1 == pytest.approx(l3, rel=1e-13)
    np.testing.assert_allclose(g1, g3, rtol=1e-11, atol=1e-13 * np.abs(g3).max())


@needs_openblas
def test_network_calls_inside_a_loss_run_serially(two_workers):
    net = make_net()
    x = points(500)
    inner = make_net(bias=False)
    seen = []

    def loss(y, JD, sl):
        seen.append(_parallel.inside_worker())
        target = inner.jet(x[sl], 0)  # a nested engine call from a worker thread
        r = y - target
        return float(np.sum(r * r)), 2 * r, None

    val, _ = net.value_and_grad(x, loss, order=0)
    ref = float(np.sum((net.jet(x, 0) - inner.jet(x, 0)) ** 2))
    assert val == pytest.approx(ref, rel=1e-12)
    workers, chunk = _parallel.plan(500, 37)
    assert workers >= 2 and len(seen) == -(-500 // chunk) and all(seen)
    assert not _parallel.inside_worker()


@needs_openblas
def test_worker_errors_propagate_and_blas_settings_are_restored(two_workers):
    libs = _parallel._blas()
    before = [lib.get() for lib in libs]
    net = make_net()
    x = points(400)

    def loss(y, JD, sl):
        if sl.start > 0:
            raise ValueError("boom from a worker")
        return 0.0, np.zeros_like(y), None

    with pytest.raises(ValueError, match="boom from a worker"):
        net.value_and_grad(x, loss, order=0)
    assert [lib.get() for lib in libs] == before
    assert not _parallel.inside_worker()
    net.jet(x, 1)  # the engine still works after a failed call
    assert [lib.get() for lib in libs] == before


@needs_openblas
def test_a_forked_child_runs_the_engine(two_workers):
    """After fork the child has no pool threads; its first parallel call must build its own."""
    import multiprocessing as mp

    net = make_net()
    x = points(300)
    ref = net.jet(x, 1)[1]  # the parent's pool exists now
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        J = pool.apply_async(_child_jet, (net.pack(), x)).get(timeout=120)  # a hang fails
    assert np.array_equal(J, ref)


def _child_jet(theta, x):
    net = make_net()
    net.unpack(theta)
    assert _parallel.plan(len(x), 37)[0] >= 1
    return net.jet(x, 1)[1]


@needs_openblas
def test_data_parallel_second_order_gradient_matches(two_workers, monkeypatch):
    """Order 2 on worker threads (the serial second-order backward kernel) equals the
    threaded path."""
    net = make_net()
    x = points(555)
    D = np.random.default_rng(5).standard_normal((555, 3, 3))

    def loss(y, JD, D2D, sl):
        r = y - 1.3 * x[sl]
        return float(np.sum(r * r) + 0.1 * np.sum(D2D * D2D)), 2 * r, 0.1 * JD, 0.2 * D2D

    assert _parallel.plan(555, 37)[0] >= 2
    l1, g1 = net.value_and_grad(x, loss, order=2, directions=D, second=2)
    monkeypatch.setattr(_parallel, "_enabled", False)
    l2, g2 = net.value_and_grad(x, loss, order=2, directions=D, second=2)
    assert l1 == pytest.approx(l2, rel=1e-13)
    np.testing.assert_allclose(g1, g2, rtol=1e-11, atol=1e-13 * np.abs(g2).max())


def test_workspace_arrays_are_aligned_disjoint_and_nest():
    ws = _engine._Workspace()
    shapes = [(3, 5, 7), (1,), (4, 4), (0, 3), (9,)]
    with ws.arrays(np.float32, *shapes) as outer:
        assert [a.shape for a in outer] == shapes and ws.level == 1
        for i, a in enumerate(outer):
            assert a.dtype == np.float32 and (a.size == 0 or a.ctypes.data % 64 == 0)
            a[...] = i
        with ws.arrays(np.float64, (6, 6)) as (inner,):   # a nested call: its own block
            inner[...] = -1.0
            assert len(ws.blocks) == 2
        for i, a in enumerate(outer):                     # nothing overwritten
            assert (a == i).all()
    assert ws.level == 0
    block = ws.blocks[0]
    with ws.arrays(np.float32, (2, 3)):                   # smaller: the same block again
        assert ws.blocks[0] is block
    with ws.arrays(np.float64, (1000, 100)):              # larger: the block grows
        assert ws.blocks[0].nbytes >= 800_000


def test_engine_reuses_its_workspace_and_releases_it():
    net = make_net(chunk_size=None)
    x = points(300)
    q = 1.3 * x
    D = np.random.default_rng(2).standard_normal((300, 3, 2))
    l1, g1 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    held = [b.ctypes.data for b in _engine._workspace.blocks]
    assert held                                   # the calling thread kept its tape
    l2, g2 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    assert [b.ctypes.data for b in _engine._workspace.blocks] == held
    assert l1 == l2 and np.array_equal(g1, g2)
    release_workspace()
    assert _engine._workspace.blocks == [] and _parallel._state["pool"] is None

    def releasing(y, JD, sl):           # from inside a call, even inside a worker: harmless
        release_workspace()
        return _loss(q)(y, JD, sl)

    l4, g4 = net.value_and_grad(x, releasing, order=1, directions=D)
    assert l1 == l4 and np.array_equal(g1, g4)
    l3, g3 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    assert l1 == l3 and np.array_equal(g1, g3)


@needs_openblas
def test_a_concurrent_loss_runs_on_two_workers_at_once(two_workers):
    """With ``concurrent_loss`` the workers' calls overlap (both reach a two-party barrier,
    which the lock would never let them do), and the result is the locked one, bit for bit."""
    import threading
    net = make_net(chunk_size=50)
    x = points(100)                     # two chunks, one per worker
    q = 1.3 * x
    D = np.random.default_rng(2).standard_normal((100, 3, 2))
    assert _parallel.plan(100, 50) == (2, 50)
    barrier = threading.Barrier(2, timeout=10)
    inner = _loss(q)

    def meeting(y, JD, sl):
        barrier.wait()
        return inner(y, JD, sl)

    l1, g1 = net.value_and_grad(x, meeting, order=1, directions=D, concurrent_loss=True)
    l2, g2 = net.value_and_grad(x, _loss(q), order=1, directions=D)
    assert l1 == l2 and np.array_equal(g1, g2)
    barrier.reset()
    quick = threading.Barrier(2, timeout=0.5)

    def alone(y, JD, sl):
        quick.wait()
        return inner(y, JD, sl)

    with pytest.raises(threading.BrokenBarrierError):   # the lock: one call at a time
        net.value_and_grad(x, alone, order=1, directions=D)
