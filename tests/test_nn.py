"""The residual network: jets and gradients against central differences, packing, files."""

import numpy as np
import pytest

from sns_np.errors import ModelFileError, ShapeError
from sns_np.nn import ResidualMLP, sigmoid, softplus
from sns_np.nn import _kernels as K
from sns_np.nn.activations import softplus_derivatives
from sns_np.testing import check_directional_jet, check_gradient, check_jet

# (width, depth, bias): the BLAS path (width > 32) and the small-network Numba path
ARCHS = [(48, 2, False), (40, 1, True), (10, 2, False), (12, 3, True), (33, 0, True)]


def make_net(width, depth, bias, seed=0, dtype=np.float64):
    net = ResidualMLP(width=width, depth=depth, bias=bias, seed=seed, dtype=dtype)
    g = np.random.default_rng(seed + 1)
    # generic parameters: non-zero biases, an output layer of order one
    net.W3[...] = g.standard_normal(net.W3.shape) / np.sqrt(width)
    for b in ("b0", "b1", "b2", "b3"):
        arr = getattr(net, b)
        arr[...] = 0.3 * g.standard_normal(arr.shape)
    return net


def test_parameter_count_of_reference_network():
    net = ResidualMLP()
    assert net.n_params == 1_050_112
    assert ResidualMLP(bias=True).n_params == 1_050_112 + 256 + 2 * 8 * 256 + 3


def test_softplus_kernel_matches_numpy_reference():
    z = np.concatenate([np.linspace(-750, 750, 3001), np.random.default_rng(0).normal(0, 8, 999)])
    z = z.reshape(4, -1)
    out = np.empty_like(z)
    K.softplus_values(z, out)
    ref = softplus(z)
    kept = (z < 700) & (z >= -K._FLUSH_Z)
    assert np.max(np.abs(out - ref)[kept] / np.abs(ref[kept])) < 1e-14
    # below -_FLUSH_Z softplus is flushed to 0: an absolute error under 1e-30
    flushed = z < -K._FLUSH_Z
    assert (out[flushed] == 0).all() and ref[flushed].max() < 1e-30
    assert np.max(np.abs(out - ref)) < 1e-30 + 1e-12 * np.max(np.abs(ref))
    assert np.allclose(sigmoid(z), np.exp(-np.logaddexp(0, -z)), rtol=1e-14, atol=0)
    s, s1, s2, s3 = softplus_derivatives(np.array([0.0]))
    assert np.allclose([s[0], s1[0], s2[0], s3[0]], [np.log(2), 0.5, 0.25, 0.0])


def test_float32_kernels_flush_what_float32_cannot_resolve():
    """float32 flushes softplus and sigmoid below z = -_FLUSH_Z32 and first-order streams and
    cotangents below _FLUSH_BAR32 (no subnormal reaches a matrix product); float64 keeps them."""
    z = np.array([[-60.0, -45.0, -39.0, 0.5]])
    for dt, flushed in ((np.float32, [True, True, False, False]),
                        (np.float64, [False, False, False, False])):
        out = np.empty_like(z, dtype=dt)
        K.softplus_values(z.astype(dt), out)
        assert ((out == 0)[0] == flushed).all()
        assert np.allclose(out[out != 0], softplus(z)[out != 0], rtol=1e-6)
        # reverse pass: sigmoid(-30) * 1e-8 = 9e-22 is flushed in float32 only
        c, m, w = 1, 2, 3
        Zs = np.zeros((c, 1 + m, w), dt)
        Zs[0, 0] = [-30.0, 0.0, 1.0]
        sig = (1 / (1 + np.exp(-Zs[:, 0, :].astype(np.float64)))).astype(dt)
        Abar = np.full((c, 1 + m, w), 1e-8, dt)
        Zbar = np.empty_like(Abar)
        K.softplus_jet_back(Zs, sig, Abar, Zbar, m)
        assert (Zbar[0, :, 0] == 0).all() == (dt == np.float32)
        assert (Zbar[0, :, 1:] != 0).all()
        assert np.allclose(Zbar[0, 1:, 1:], sig[0, 1:] * 1e-8, rtol=1e-6)
        # a NaN cotangent is never flushed: divergence must stay visible
        Abar[0, 1, 0] = np.nan
        K.softplus_jet_back(Zs, sig, Abar, Zbar, m)
        assert np.isnan(Zbar[0, 1, 0]) and np.isnan(Zbar[0, 0, 0])


def test_float32_jet_kernel_is_accurate_to_float32():
    """The float32 rows compute softplus and sigmoid in float32 arithmetic: within a few
    units in the last place of the float64 values, over the whole range that is not flushed;
    the Python body (without the JIT) makes the same choice by dtype."""
    z = np.concatenate([np.linspace(-40, 88, 6401), np.random.default_rng(4).normal(0, 10, 1599)])
    z = z[z >= -K._FLUSH_Z32][:7968]
    z = z.reshape(-1, 1, 32)          # (c, S = 1, w) streams, m = k = 0
    x = z[:, 0].astype(np.float32).astype(np.float64)     # the float32 inputs, exactly
    ref_a, ref_s = softplus(x), sigmoid(x)
    for dt, rtol in ((np.float32, 4e-7), (np.float64, 1e-14)):
        Z = z.astype(np.float32).astype(dt)
        out, sig = np.empty_like(Z), np.empty((Z.shape[0], Z.shape[2]), dt)
        K.softplus_jet_serial(Z.copy(), Z, np.zeros(32, dt), out, sig, 0, 0, False, False)
        assert np.max(np.abs(out[:, 0] - ref_a) / ref_a) < rtol, dt
        assert np.max(np.abs(sig - ref_s) / ref_s) < rtol, dt
        # the dispatching helper called from Python (as without the JIT)
        p, a, s, s2 = (np.empty(32, dt) for _ in range(4))
        K._softplus_parts(Z[0, 0], p, np.empty(32, np.int64), a, s, s2)
        assert a.dtype == dt
        np.testing.assert_allclose(a, ref_a[0], rtol=rtol)
        np.testing.assert_allclose(s, ref_s[0], rtol=rtol)
        np.testing.assert_allclose(s2, ref_s[0] * (1 - ref_s[0]), rtol=4 * rtol)


def test_fused_jet_kernel_against_formula():
    g = np.random.default_rng(3)
    c, m, k, w = 5, 3, 2, 37
    S = 1 + m + k * (k + 1) // 2
    Z = g.standard_normal((c, S, w)) * 3
    out = np.empty_like(Z)
    sig = np.empty((c, w))
    bias = g.standard_normal(w)
    Zin = Z.copy()
    K.softplus_jet(Z, Z, bias, out, sig, m, k, False, True)
    z = Zin[:, 0] + bias
    s0, s1, s2 = softplus_derivatives(z, 2)
    assert np.allclose(Z[:, 0], z)                        # bias written back for the tape
    assert np.allclose(out[:, 0], s0, rtol=1e-14)
    assert np.allclose(sig, s1, rtol=1e-14)
    for a in range(m):
        assert np.allclose(out[:, 1 + a], s1 * Zin[:, 1 + a], rtol=1e-13)
    q = 1 + m
    for a in range(k):
        for b in range(a, k):
            ref = s2 * Zin[:, 1 + a] * Zin[:, 1 + b] + s1 * Zin[:, q]
            assert np.allclose(out[:, q], ref, rtol=1e-12, atol=1e-14)
            q += 1


@pytest.mark.parametrize("width,depth,bias", ARCHS)
def test_jacobian_and_hessian_match_central_differences(width, depth, bias):
    net = make_net(width, depth, bias)
    x = np.random.default_rng(7).standard_normal((25, 3))
    y, J, D2 = net.jet(x, 2)
    assert y.shape == (25, 3) and J.shape == (25, 3, 3) and D2.shape == (25, 3, 3, 3)
    err = check_jet(net, x, order=2, h=1e-4, richardson=True)
    assert err["J"] < 1e-6, err
    assert err["D2"] < 1e-6, err
    assert err["D2_symmetry"] == 0.0
    # orders agree with each other
    y1, J1 = net.jet(x, 1)
    assert np.array_equal(net.jet(x, 0), y) or np.allclose(net.jet(x, 0), y, rtol=1e-14)
    assert np.allclose(J1, J, rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("width,depth,bias", ARCHS[:3])
def test_directional_jets(width, depth, bias):
    net = make_net(width, depth, bias)
    g = np.random.default_rng(11)
    x = g.standard_normal((19, 3))
    D = g.standard_normal((19, 3, 3))
    for second in (None, 2, 0):
        err = check_directional_jet(net, x, D, order=2, second=second, h=1e-4, richardson=True)
        assert err["JD_vs_full"] < 1e-12 and err["D2D_vs_full"] < 1e-12, err
        assert err["JD_vs_fd"] < 1e-6 and err["D2D_vs_fd"] < 1e-6, err
    y, JD, D2D = net.jet(x, 2, directions=D, second=2)
    assert JD.shape == (19, 3, 3) and D2D.shape == (19, 3, 2, 2)
    y1, JD1 = net.jet(x, 1, directions=D[:, :, :2])
    assert JD1.shape == (19, 3, 2) and np.allclose(JD1, JD[:, :, :2], rtol=1e-13, atol=1e-15)


def _loss_and_grad(net, x, dy, dJ, D=None):
    def fun(theta):
        net.unpack(theta)
        loss = 0.0
        if dJ is None:
            loss = np.sum(dy * net.jet(x, 0))
        else:
            y, J = net.jet(x, 1, directions=D) if D is not None else net.jet(x, 1)
            loss = np.sum(dy * y) + np.sum(dJ * J)
        return float(loss), net.vjp(x, dy, dJ, directions=D)
    return fun


@pytest.mark.parametrize("width,depth,bias", [(6, 1, True), (34, 1, True)])
@pytest.mark.parametrize("which", ["dy", "dJ", "both"])
def test_vjp_every_parameter_of_a_tiny_network(width, depth, bias, which):
    net = make_net(width, depth, bias, seed=2)
    g = np.random.default_rng(5)
    x = g.standard_normal((9, 3))
    dy = g.standard_normal((9, 3)) if which != "dJ" else np.zeros((9, 3))
    dJ = g.standard_normal((9, 3, 3)) if which != "dy" else None
    fun = _loss_and_grad(net, x, dy, dJ)
    err = check_gradient(fun, net.pack(), h=1e-5, n_directions=None)
    assert err < 1e-6, err


@pytest.mark.parametrize("width,depth,bias", [(64, 3, False), (20, 2, True)])
def test_vjp_random_directions_larger_network(width, depth, bias):
    net = make_net(width, depth, bias, seed=4)
    g = np.random.default_rng(6)
    x = g.standard_normal((40, 3))
    dy, dJ = g.standard_normal((40, 3)), g.standard_normal((40, 3, 3))
    D = g.standard_normal((40, 3, 2))
    dJD = g.standard_normal((40, 3, 2))
    for fun in (_loss_and_grad(net, x, dy, dJ), _loss_and_grad(net, x, dy, dJD, D)):
        err = check_gradient(fun, net.pack(), h=1e-5, n_directions=12, rng=0, richardson=True)
        assert err < 1e-7, err


def test_value_and_grad_chunks_and_loss_sum():
    """A mean-squared loss through value_and_grad equals the same loss via vjp, any chunking."""
    g = np.random.default_rng(8)
    x = g.standard_normal((300, 3))
    target = g.standard_normal((300, 3))
    results = []
    for chunk in (None, 7, 300):
        net = make_net(40, 2, False, seed=9)
        net.chunk_size = chunk

        def loss(y, JD, sl):
            r = y - target[sl]
            dJ = 0.1 * JD
            return (r ** 2).sum() / 300 + 0.05 * (JD ** 2).sum(), 2 * r / 300, dJ

        results.append(net.value_and_grad(x, loss, order=1))
    for val, grad in results[1:]:
        assert np.isclose(val, results[0][0], rtol=1e-12)
        assert np.allclose(grad, results[0][1], rtol=1e-10, atol=1e-13)
    net = make_net(40, 2, False, seed=9)
    y, J = net.jet(x, 1)
    ref = net.vjp(x, 2 * (y - target) / 300, 0.1 * J)
    assert np.allclose(results[0][1], ref, rtol=1e-10, atol=1e-13)


def test_chunking_does_not_change_jets():
    x = np.random.default_rng(1).standard_normal((101, 3))
    a = make_net(64, 2, True)
    b = make_net(64, 2, True)
    b.chunk_size = 6
    for pa, pb in zip(a.jet(x, 2), b.jet(x, 2)):
        assert np.allclose(pa, pb, rtol=1e-13, atol=1e-15)


def test_small_kernels_are_compiled_once_per_dtype():
    # every argument layout is a separate Numba compilation (seconds each in a fresh
    # environment): axes, given directions, read-only and strided inputs share one
    from sns_np.nn import _kernels as K
    if not hasattr(K.small_forward, "signatures"):
        pytest.skip("Numba's JIT is disabled (NUMBA_DISABLE_JIT=1): nothing is compiled")
    net = make_net(10, 2, True)
    x = np.random.default_rng(4).standard_normal((20, 3))
    ro = x.copy()
    ro.flags.writeable = False
    D = np.random.default_rng(5).standard_normal((20, 3, 2))
    for order in (0, 1, 2):
        net.jet(x, order)
    net.jet(ro, 1)
    net.jet(np.asfortranarray(x), 2)
    net.jet(x, 2, directions=D)
    net.jet(x, 1, directions=D[:, :, ::-1])
    net.vjp(x, np.ones((20, 3)))
    net.vjp(ro, np.ones((20, 3)))
    for kernel in (K.small_forward, K.small_vjp):
        layouts = {(sig[0].layout, sig[0].mutable, sig[1].layout, sig[1].mutable)
                   for sig in kernel.signatures}
        assert layouts == {("C", True, "C", True)}, (kernel.__name__, kernel.signatures)


@pytest.mark.parametrize("width", [10, 64])
def test_float32_network_agrees_with_float64(width):
    n64 = make_net(width, 2, True)
    n32 = n64.astype(np.float32)
    x = np.random.default_rng(2).standard_normal((50, 3))
    for a64, a32 in zip(n64.jet(x, 2), n32.jet(x, 2)):
        assert a32.dtype == np.float32
        scale = np.max(np.abs(a64))
        assert np.max(np.abs(a32 - a64)) < 1e-4 * scale
    dy = np.random.default_rng(3).standard_normal((50, 3))
    g64, g32 = n64.vjp(x, dy), n32.vjp(x, dy)
    assert g32.dtype == np.float32
    assert np.max(np.abs(g32 - g64)) < 1e-3 * np.max(np.abs(g64))


def test_pack_unpack_and_views():
    net = make_net(12, 2, True)
    theta = net.pack()
    W1 = net.W1
    assert theta.shape == (net.n_params,)
    new = np.arange(net.n_params, dtype=np.float64) / net.n_params
    net.unpack(new)
    assert np.array_equal(net.pack(), new)
    assert np.shares_memory(W1, net.theta) and W1[0, 0, 0] == net.W1[0, 0, 0]
    sl, shape = net.param_slices()["W2"]
    assert np.array_equal(new[sl].reshape(shape), net.W2)
    theta[0] = 123.0  # pack returns a copy
    assert net.theta[0] != 123.0


def test_save_load_round_trip(tmp_path):
    for dtype in (np.float64, np.float32):
        net = make_net(20, 2, True, dtype=dtype)
        path = net.save(tmp_path / f"net_{np.dtype(dtype).name}.npz")
        back = ResidualMLP.load(path)
        assert back.architecture() == net.architecture() and back.dtype == net.dtype
        assert np.array_equal(back.pack(), net.pack())
        x = np.random.default_rng(0).standard_normal((5, 3))
        assert np.array_equal(back.jet(x, 0), net.jet(x, 0))
    assert not list(tmp_path.glob("*.tmp"))


def test_load_rejects_foreign_and_corrupt_files(tmp_path):
    net = make_net(10, 1, False)
    good = net.save(tmp_path / "good.npz")
    with pytest.raises(ModelFileError, match="does not exist"):
        ResidualMLP.load(tmp_path / "missing.npz")
    bad = tmp_path / "garbage.npz"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(ModelFileError, match="not a readable"):
        ResidualMLP.load(bad)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, weights=np.zeros(3))
    with pytest.raises(ModelFileError, match="missing field"):
        ResidualMLP.load(foreign)
    state = dict(np.load(good))
    state["format_version"] = np.array(99)
    np.savez(tmp_path / "future.npz", **state)
    with pytest.raises(ModelFileError, match="version 99"):
        ResidualMLP.load(tmp_path / "future.npz")
    state = dict(np.load(good))
    state["theta"] = state["theta"][:-1]
    np.savez(tmp_path / "short.npz", **state)
    with pytest.raises(ModelFileError, match="parameter vector"):
        ResidualMLP.load(tmp_path / "short.npz")
    state = dict(np.load(good))
    state["theta"] = np.array([object()] * 3, dtype=object)
    np.savez(tmp_path / "pickled.npz", **state)
    with pytest.raises(ModelFileError, match="cannot be read safely"):
        ResidualMLP.load(tmp_path / "pickled.npz")


def test_bad_inputs_are_rejected():
    net = make_net(10, 1, False)
    with pytest.raises(ShapeError, match=r"shape \(n, 3\)"):
        net.jet(np.zeros((4, 2)))
    with pytest.raises(ShapeError, match="non-finite"):
        net.jet(np.array([[0.0, np.nan, 1.0]]))
    with pytest.raises(ShapeError, match="real floating"):
        net.jet(np.zeros((2, 3), dtype=complex))
    with pytest.raises(ValueError, match="order must be"):
        net.jet(np.zeros((2, 3)), order=3)
    with pytest.raises(ShapeError, match="directions must have shape"):
        net.jet(np.zeros((2, 3)), 1, directions=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="second"):
        net.jet(np.zeros((2, 3)), 2, directions=np.zeros((2, 3, 2)), second=3)
    with pytest.raises(ShapeError, match="theta must have shape"):
        net.unpack(np.zeros(net.n_params + 1))
    with pytest.raises(ShapeError, match="real floating"):
        net.unpack(np.zeros(net.n_params, dtype=np.int64))
    with pytest.raises(ShapeError, match="dJ must have shape"):
        net.vjp(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3, 2)))
    with pytest.raises(ValueError, match="dtype must be"):
        ResidualMLP(dtype=np.int32)
    with pytest.raises(ValueError, match="width must be"):
        ResidualMLP(width=0)
    with pytest.raises(ValueError, match=r"\.npz"):
        net.save("model.txt")


@pytest.mark.slow_nojit
def test_large_input_is_chunked_and_bounded():
    """1,000,000 points through a wide network: works, and the result matches small calls."""
    net = make_net(40, 1, False)
    x = np.random.default_rng(0).standard_normal((1_000_000, 3))
    y = net.jet(x, 0)
    assert y.shape == (1_000_000, 3) and np.all(np.isfinite(y))
    assert np.allclose(y[-5:], net.jet(x[-5:], 0), rtol=1e-13)


def _features_by_hand(net, x):
    """The hidden features recomputed from the parameters: plain NumPy, logaddexp softplus."""
    sp = lambda z: np.logaddexp(0.0, z)
    h = sp(x @ net.W0.T + (net.b0 if net.bias else 0.0))
    for blk in range(net.depth):
        a = sp(h @ net.W1[blk].T + (net.b1[blk] if net.bias else 0.0))
        h = sp(h + a @ net.W2[blk].T + (net.b2[blk] if net.bias else 0.0))
    return h


@pytest.mark.parametrize("width, depth, bias", [(12, 3, True), (48, 2, False), (40, 1, True)])
@pytest.mark.parametrize("dtype, rtol", [(np.float64, 1e-12), (np.float32, 2e-5)])
def test_features_match_a_numpy_recomputation(width, depth, bias, dtype, rtol):
    net = make_net(width, depth, bias, seed=3).astype(dtype)
    x = np.random.default_rng(4).standard_normal((300, 3))
    h = net.features(x, chunk_size=77)                   # several chunks, one partial
    assert h.shape == (300, width) and h.dtype == np.dtype(dtype)
    ref = _features_by_hand(net.astype(np.float64), x)
    np.testing.assert_allclose(h, ref, rtol=rtol, atol=rtol * np.abs(ref).max())
    # the read-out of the features is the network's value (small-width kernel or BLAS path)
    y = h.astype(np.float64) @ net.W3.T.astype(np.float64) + (net.b3 if bias else 0.0)
    np.testing.assert_allclose(net(x), y, rtol=10 * rtol, atol=10 * rtol * np.abs(y).max())


@pytest.mark.parametrize("width, bias", [(12, True), (40, False)])
def test_fit_readout_recovers_an_exact_read_out(width, bias):
    net = make_net(width, 2, bias, seed=5)
    x = np.random.default_rng(6).standard_normal((400, 3))
    g = np.random.default_rng(7)
    W, b = g.standard_normal((3, width)), g.standard_normal(3) if bias else np.zeros(3)
    target = net.features(x) @ W.T + b
    T = net.fit_readout(x, target, rel_reg=0.0)
    assert T.shape == (width + bias, 3)
    np.testing.assert_allclose(net.W3, W, atol=1e-6)
    np.testing.assert_allclose(net(x), target, atol=1e-8)
    if bias:
        np.testing.assert_allclose(net.b3, b, atol=1e-6)
    # fitted already: an increment changes (almost) nothing
    before = net.pack()
    d = net.fit_readout(x, target, increment=True)
    assert np.abs(d).max() < 1e-6
    np.testing.assert_allclose(net.pack(), before, atol=1e-6)


def test_fit_readout_increment_replace_weights_and_scalar():
    net = make_net(16, 2, True, seed=8)
    x = np.random.default_rng(9).standard_normal((300, 3))
    target = np.sin(x) + 0.1 * x ** 2
    # without a ridge, replacing and incrementing reach the same least-squares read-out
    a, b = net.copy(), net.copy()
    a.fit_readout(x, target, rel_reg=0.0)
    b.fit_readout(x, target, rel_reg=0.0, increment=True)
    np.testing.assert_allclose(a(x), b(x), atol=1e-8)
    # zero weights drop points: the same fit as on the others alone
    w = np.r_[np.ones(200), np.zeros(100)]
    c, d = net.copy(), net.copy()
    c.fit_readout(x, target + np.r_[np.zeros((200, 3)), 9.0 * np.ones((100, 3))], weights=w)
    d.fit_readout(x[:200], target[:200])
    np.testing.assert_allclose(c.theta, d.theta, atol=1e-8)
    # the only parameters changed are W3 and b3
    sl = net.param_slices()
    changed = [k for k, (s, _) in sl.items() if not np.array_equal(c.theta[s], net.theta[s])]
    assert changed == ["W3", "b3"]
    # a scalar read-out g = scale * mean(y): one common change to every output row
    scale = 0.7
    e = np.random.default_rng(10).standard_normal(17)
    g0 = scale * net(x).mean(axis=1)
    goal = g0 + scale * (np.hstack([net.features(x), np.ones((300, 1))]) @ e)
    s = net.copy()
    T = s.fit_readout(x, goal, increment=True, scale=scale, rel_reg=0.0)
    np.testing.assert_allclose(T, e, atol=1e-6)
    np.testing.assert_allclose(scale * s(x).mean(axis=1), goal, atol=1e-8)
    np.testing.assert_allclose(s.W3 - net.W3, np.tile(e[:16], (3, 1)), atol=1e-6)
    same = net.copy()
    same.fit_readout(x, goal, increment=True, scale=scale, rel_reg=0.0, current=g0)
    np.testing.assert_allclose(same.theta, s.theta, atol=1e-9)


def test_fit_readout_rejects_bad_input_and_keeps_a_non_finite_fit_out():
    net = make_net(12, 1, False)
    x = np.random.default_rng(11).standard_normal((50, 3))
    with pytest.raises(ShapeError, match="target"):
        net.fit_readout(x, np.zeros((50, 2)))
    with pytest.raises(ValueError, match="increment=True"):
        net.fit_readout(x, np.zeros(50))
    with pytest.raises(ShapeError, match="weights"):
        net.fit_readout(x, np.zeros((50, 3)), weights=np.ones(49))
    with pytest.raises(ValueError, match="non-negative"):
        net.fit_readout(x, np.zeros((50, 3)), weights=-np.ones(50))
    with pytest.raises(ShapeError, match="current"):
        net.fit_readout(x, np.zeros(50), increment=True, current=np.zeros((50, 3)))
    before = net.pack()
    T = net.fit_readout(x, np.full((50, 3), np.nan))
    assert not np.all(np.isfinite(T)) and np.array_equal(net.pack(), before)


def _second_order_loss(net, x, D, k, seed):
    """A quadratic loss on y, JD and D2D (k pairs) and, per chunk, its cotangents; the loss
    alone from net.jet for the central differences."""
    g = np.random.default_rng(seed)
    n, m = D.shape[0], D.shape[2]
    T0, T1 = g.standard_normal((n, 3)), g.standard_normal((n, 3, m))
    T2 = g.standard_normal((n, 3, k, k))
    T2 = T2 + np.swapaxes(T2, 2, 3)

    def loss_fn(y, JD, D2D, sl):
        r, e, h = y - T0[sl], JD - T1[sl], D2D - T2[sl]
        return ((r ** 2).sum() + 0.5 * (e ** 2).sum() + 0.3 * (h ** 2).sum(),
                2 * r, e, 0.6 * h)

    def fun(theta):
        net.unpack(theta)
        y, JD, D2D = net.jet(x, 2, directions=D, second=k)
        return (loss_fn(y, JD, D2D, slice(None))[0],
                net.value_and_grad(x, loss_fn, order=2, directions=D, second=k)[1])
    return fun, loss_fn


@pytest.mark.parametrize("width,depth,bias", [(48, 2, True), (10, 1, False), (40, 0, True)])
@pytest.mark.parametrize("m,k", [(3, 2), (2, 2), (3, 3)])
def test_value_and_grad_of_second_derivatives_matches_central_differences(width, depth, bias,
                                                                          m, k):
    """Order 2: the reverse pass through the second-order jet rule (both paths: a width <= 32
    takes the BLAS path too), every parameter family, against central differences."""
    net = make_net(width, depth, bias, seed=11)
    g = np.random.default_rng(12)
    x = g.standard_normal((23, 3))
    D = g.standard_normal((23, 3, m))
    fun, loss_fn = _second_order_loss(net, x, D, k, 13)
    err = check_gradient(fun, net.pack(), h=1e-5, n_directions=12, rng=0, richardson=True)
    assert err < 1e-7, err
    theta = net.pack()
    y, JD, D2D = net.jet(x, 2, directions=D, second=k)
    val, grad = net.value_and_grad(x, loss_fn, order=2, directions=D, second=k)
    assert val == pytest.approx(loss_fn(y, JD, D2D, slice(None))[0], rel=1e-12)
    net.chunk_size = 5                                       # chunking changes nothing
    val5, grad5 = net.value_and_grad(x, loss_fn, order=2, directions=D, second=k)
    assert val5 == pytest.approx(val, rel=1e-12)
    np.testing.assert_allclose(grad5, grad, rtol=1e-10, atol=1e-13 * np.abs(grad).max())
    assert np.array_equal(net.pack(), theta)


def test_value_and_grad_second_order_agrees_with_first_order_without_second_cotangents():
    """A loss that ignores D2D gives order 1's gradient: the extra streams only add."""
    net = make_net(40, 2, True, seed=14)
    g = np.random.default_rng(15)
    x, D = g.standard_normal((31, 3)), g.standard_normal((31, 3, 3))
    q = g.standard_normal((31, 3))

    def loss1(y, JD, sl):
        r = y - q[sl]
        return (r ** 2).sum(), 2 * r, 0.2 * JD

    def loss2(y, JD, D2D, sl):
        return (*loss1(y, JD, sl), None)

    v1, g1 = net.value_and_grad(x, loss1, order=1, directions=D)
    v2, g2 = net.value_and_grad(x, loss2, order=2, directions=D, second=2)
    assert v2 == pytest.approx(v1, rel=1e-13)
    np.testing.assert_allclose(g2, g1, rtol=1e-11, atol=1e-14 * np.abs(g1).max())


def test_value_and_grad_order_two_options_are_checked():
    net = make_net(40, 1, False)
    x = np.zeros((4, 3))
    with pytest.raises(ValueError, match="second must be an integer in"):
        net.value_and_grad(x, None, order=2, directions=np.ones((4, 3, 2)), second=3)
    with pytest.raises(ValueError, match="second= needs order=2"):
        net.value_and_grad(x, None, order=1, directions=np.ones((4, 3, 2)), second=1)
    with pytest.raises(ValueError, match="order must be one of"):
        net.value_and_grad(x, None, order=3)
