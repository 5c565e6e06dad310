"""Optimisers: first steps re-derived by hand, schedules, state round trips, scipy."""

import math

import numpy as np
import pytest
import scipy.optimize

from sns_np.errors import DivergenceError, ShapeError
from sns_np.nn import (
    SGD,
    Adam,
    ResidualMLP,
    RMSProp,
    Schedule,
    cosine,
    make_optimizer,
    scipy_objective,
    step,
)

G1 = np.array([0.5, -2.0, 0.0, 1e-3])
G2 = np.array([-1.0, 1.0, 3.0, 1e-3])


def test_adam_first_two_steps_by_hand():
    theta = np.array([1.0, 2.0, 3.0, 4.0])
    opt = Adam(lr=0.1, betas=(0.9, 0.999), eps=1e-8)
    opt.step(theta, G1)
    # step 1: m = 0.1 g, v = 0.001 g^2, bias-corrected m^ = g, v^ = g^2 -> update lr g/(|g|+eps)
    expected = np.array([1.0, 2.0, 3.0, 4.0]) - 0.1 * G1 / (np.abs(G1) + 1e-8)
    assert np.allclose(theta, expected, rtol=1e-12)
    opt.step(theta, G2)
    m = 0.9 * (0.1 * G1) + 0.1 * G2
    v = 0.999 * (0.001 * G1 ** 2) + 0.001 * G2 ** 2
    mhat, vhat = m / (1 - 0.9 ** 2), v / (1 - 0.999 ** 2)
    expected = expected - 0.1 * mhat / (np.sqrt(vhat) + 1e-8)
    assert np.allclose(theta, expected, rtol=1e-12)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_adam_fused_update_matches_the_formula(dtype):
    """Long vectors take the fused Numba update; three steps against the formula in float64."""
    from sns_np.nn.optim import _FUSED_MIN
    g = np.random.default_rng(7)
    n = _FUSED_MIN + 5
    theta0 = g.standard_normal(n)
    grads = [g.standard_normal(n) * 10.0 ** g.uniform(-6, 1, n) for _ in range(3)]
    theta = theta0.astype(dtype)
    opt = Adam(lr=0.01, betas=(0.9, 0.999), eps=1e-8)
    m = v = np.zeros(n)
    expected = theta0.copy()
    for t, gt in enumerate(grads, start=1):
        opt.step(theta, gt.astype(dtype))
        m = 0.9 * m + 0.1 * gt
        v = 0.999 * v + 0.001 * gt ** 2
        expected -= 0.01 * (m / (1 - 0.9 ** t)) / (np.sqrt(v / (1 - 0.999 ** t)) + 1e-8)
    # float32: theta (about 1) is rounded at every step, a few units of 6e-8
    tol = 1e-13 if dtype == np.float64 else 1e-6
    assert theta.dtype == dtype
    assert np.abs(theta - expected).max() < tol


def test_adam_float32_moments_never_subnormal():
    """A gradient that has died out leaves zero moments in float32, not subnormal ones."""
    from sns_np.nn.optim import _FUSED_MIN
    n = _FUSED_MIN
    tiny = np.finfo(np.float32).tiny
    theta = np.ones(n, np.float32)
    opt = Adam(lr=1e-3)
    grad = np.full(n, 1e-15, np.float32)          # g^2 = 1e-30: normal
    opt.step(theta, grad)
    grad[:] = 1e-21                               # g^2 = 1e-42 would be subnormal
    for _ in range(3):
        opt.step(theta, grad)
    m, v = opt.state_dict()["m"], opt.state_dict()["v"]
    for moment in (m, v):
        assert not ((moment != 0) & (np.abs(moment) < tiny)).any()
    assert (v > 0).all()                          # the normal part of v is kept
    assert np.isfinite(theta).all()


def test_rmsprop_with_momentum_by_hand():
    theta = np.zeros(4)
    opt = RMSProp(lr=0.01, alpha=0.99, eps=1e-8, momentum=0.9)
    opt.step(theta, G1)
    v1 = 0.01 * G1 ** 2
    b1 = G1 / (np.sqrt(v1) + 1e-8)
    assert np.allclose(theta, -0.01 * b1, rtol=1e-12)
    opt.step(theta, G2)
    v2 = 0.99 * v1 + 0.01 * G2 ** 2
    b2 = 0.9 * b1 + G2 / (np.sqrt(v2) + 1e-8)
    assert np.allclose(theta, -0.01 * b1 - 0.01 * b2, rtol=1e-12)


def test_rmsprop_without_momentum_and_sgd():
    theta = np.zeros(4)
    RMSProp(lr=0.5, alpha=0.9, momentum=0.0).step(theta, G1)
    assert np.allclose(theta, -0.5 * G1 / (np.sqrt(0.1 * G1 ** 2) + 1e-8))
    theta = np.ones(4)
    opt = SGD(lr=0.1, momentum=0.5, nesterov=True)
    opt.step(theta, G1)
    opt.step(theta, G2)
    buf1 = G1
    buf2 = 0.5 * buf1 + G2
    expected = 1 - 0.1 * (G1 + 0.5 * buf1) - 0.1 * (G2 + 0.5 * buf2)
    assert np.allclose(theta, expected)
    theta = np.ones(4)
    SGD(lr=0.2).step(theta, G1)
    assert np.allclose(theta, 1 - 0.2 * G1)


def test_schedules():
    c = cosine(1.0, total=10, lr_min=0.1)
    assert c(0) == 1.0 and math.isclose(c(10), 0.1) and math.isclose(c(20), 0.1)
    assert math.isclose(c(5), 0.1 + 0.45 * (1 + math.cos(math.pi / 2)))
    s = step(1.0, every=3, gamma=0.1)
    assert [s(t) for t in (0, 2, 3, 6)] == pytest.approx([1, 1, 0.1, 0.01])
    w = Schedule("constant", 2.0, warmup=4)
    assert [w(t) for t in range(5)] == pytest.approx([0.5, 1.0, 1.5, 2.0, 2.0])
    opt = Adam(lr=cosine(0.1, total=2))
    theta = np.zeros(1)
    lrs = []
    for _ in range(3):
        lrs.append(opt.lr())
        opt.step(theta, np.ones(1))
    assert lrs == pytest.approx([0.1, 0.05, 0.0])
    with pytest.raises(ValueError, match="total="):
        Schedule("cosine", 1.0)
    with pytest.raises(ValueError, match="unknown schedule"):
        Schedule("linear", 1.0)


def test_state_round_trip_continues_identically():
    g = np.random.default_rng(0)
    grads = [g.standard_normal(6) for _ in range(6)]
    for make in (lambda: Adam(lr=0.05), lambda: RMSProp(lr=0.05), lambda: SGD(0.1, 0.9)):
        a, theta_a = make(), np.ones(6)
        for gr in grads:
            a.step(theta_a, gr)
        b, theta_b = make(), np.ones(6)
        for gr in grads[:3]:
            b.step(theta_b, gr)
        c = make().load_state_dict(b.state_dict())
        for gr in grads[3:]:
            c.step(theta_b, gr)
        assert np.array_equal(theta_a, theta_b)
    with pytest.raises(ValueError, match="not 'Adam'"):
        Adam().load_state_dict(RMSProp().state_dict())


def test_bad_steps():
    opt = Adam()
    theta = np.zeros(3)
    with pytest.raises(ShapeError, match="grad has shape"):
        opt.step(theta, np.zeros(4))
    with pytest.raises(DivergenceError, match="non-finite gradient"):
        opt.step(theta, np.array([0.0, np.nan, 1.0]))
    assert np.array_equal(theta, np.zeros(3))
    with pytest.raises(ValueError, match="unknown optimiser"):
        make_optimizer("lbfgs", 1e-3)
    with pytest.raises(ValueError, match="betas"):
        Adam(betas=(1.0, 0.9))


def test_scipy_lbfgs_fits_a_small_network():
    g = np.random.default_rng(1)
    x = g.standard_normal((200, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    target = x * np.array([1.0, 1.3, 0.7])
    net = ResidualMLP(width=10, depth=2, seed=0)

    def loss(y, JD, sl):
        r = y - target[sl]
        return (r ** 2).sum() / len(x), 2 * r / len(x), None

    fun = scipy_objective(net, x, loss, order=0)
    theta0 = net.pack()
    f0 = fun(theta0)[0]
    res = scipy.optimize.minimize(fun, theta0, jac=True, method="L-BFGS-B",
                                  options=dict(maxiter=300))
    assert res.fun < 1e-3 * f0
    assert np.isclose(res.fun, fun(res.x)[0])
