"""Optimisers: first steps re-derived by hand, schedules, state round trips, scipy."""

import math

import numpy as np
import pytest
import scipy.optimize

from sns_np.errors import DivergenceError, ShapeError
from sns_np.nn import (
    SGD,
    SOAP,
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


# ------------------------------------------------------------------------------ SOAP

def _matrix_problem(seed=3, p=6, q=5, well_conditioned=False):
    """min_W 0.5 |P W Q - C|^2 over a p x q matrix, plus two free numbers (Adam's part)."""
    g = np.random.default_rng(seed)
    if well_conditioned:
        P = np.eye(p) + 0.2 * g.standard_normal((p, p))
        Q = np.eye(q) + 0.2 * g.standard_normal((q, q))
    else:
        P = g.standard_normal((p, p)) * np.logspace(0, 1, p)
        Q = g.standard_normal((q, q))
    C = g.standard_normal((p, q))

    def grad(theta):
        W = theta[: p * q].reshape(p, q)
        GW = P.T @ (P @ W @ Q - C) @ Q.T
        return np.concatenate([GW.ravel(), 2 * (theta[p * q:] - 1.0)])

    return grad, [(slice(0, p * q), (p, q))], g.standard_normal(p * q + 2)


def test_soap_first_step_is_the_polar_factor_of_the_gradient():
    """After one gradient, Q_L and Q_R are its singular vectors: G~ is diagonal, and Adam's
    first step (lr sign) becomes lr U V^T, the orthogonal polar factor of G = U S V^T. (For a
    gradient whose singular values span many decades, the rounding noise off the diagonal of
    G~ rises above eps and Adam's scaling lifts it: the identity holds for a well-scaled G.)"""
    g = np.random.default_rng(5).standard_normal(32)
    G = g[:30].reshape(6, 5)
    U, _, Vt = np.linalg.svd(G, full_matrices=False)
    theta = np.zeros(32)
    SOAP(lr=0.1, matrices=[(slice(0, 30), (6, 5))]).step(theta, g)
    assert np.allclose(-theta[:30].reshape(6, 5), 0.1 * U @ Vt, atol=1e-7)
    assert np.allclose(-theta[30:], 0.1 * np.sign(g[30:]))          # Adam's first step


@pytest.mark.parametrize("kind", ["soap", "adam"])
def test_soap_is_equivariant_under_rotations_and_adam_is_not(kind):
    """Write the matrix in rotated coordinates, W = A W' B (A, B orthogonal): SOAP's iterates
    are the rotated iterates, step for step (through several new bases); Adam's are not.
    Equal to within 1e-6: the first step's rounding off the diagonal of G~ (1e-12 here) is
    divided by eps like any coordinate, and stays at that level; Adam is off by 1e-2 and more.
    (A square, well-conditioned problem: see the note of the test above.)"""
    grad, blocks, theta = _matrix_problem(p=6, q=6, well_conditioned=True)
    g = np.random.default_rng(11)
    A, B = (np.linalg.qr(g.standard_normal((6, 6)))[0] for _ in range(2))

    def rotated_grad(phi):                 # gradient of f(A W' B) in W'
        th = phi.copy()
        th[:36] = (A @ phi[:36].reshape(6, 6) @ B).ravel()
        gr = grad(th)
        gr[:36] = (A.T @ gr[:36].reshape(6, 6) @ B.T).ravel()
        return gr

    phi = theta.copy()
    phi[:36] = (A.T @ theta[:36].reshape(6, 6) @ B.T).ravel()
    make = (lambda: SOAP(lr=0.02, matrices=blocks, every=4)) if kind == "soap" else \
        (lambda: Adam(lr=0.02))
    o1, o2 = make(), make()
    for _ in range(25):
        o1.step(theta, grad(theta))
        o2.step(phi, rotated_grad(phi))
    gap = np.abs(A @ phi[:36].reshape(6, 6) @ B - theta[:36].reshape(6, 6)).max()
    assert (gap < 1e-6) if kind == "soap" else (gap > 1e-2)


@pytest.mark.parametrize("clip", [None, 1.0, 0.5])
def test_soap_clips_the_direction_in_its_eigenbasis(clip):
    """A gradient whose dominant direction turns every 40 steps: after a change of basis the
    first moment, carried into the new basis, meets a second moment kept by index, and the
    direction m^ / sqrt(v^) leaves Adam's steady range [-1, 1] unless clipped. The direction
    is read back from the step: D = Q_L^T (-dW) Q_R / (lr / (1 - b1^t))."""
    g = np.random.default_rng(3)
    p = q = 8
    U, V = (np.linalg.qr(g.standard_normal((p, p)))[0] for _ in range(2))
    lr = 1e-3
    opt = SOAP(lr=lr, matrices=[(slice(0, p * q), (p, q))], every=5, clip=clip)
    theta = np.zeros(p * q)
    worst = 0.0
    for t in range(1, 201):
        k = ((t - 1) // 40) % p
        G = 10 * np.outer(U[:, k], V[:, k]) + 1e-3 * g.standard_normal((p, q))
        before = theta.copy()
        opt.step(theta, G.ravel())
        QL, QR = opt._state["QL0"][0], opt._state["QR0"][0]
        D = QL.T @ (before - theta).reshape(p, q) @ QR * (1 - 0.9 ** t) / lr
        worst = max(worst, np.abs(D).max())
    if clip is None:
        assert worst > 2.0                  # the failure the clip exists for
    else:
        assert clip * 0.99 < worst <= clip * (1 + 1e-9)


def test_soap_shortens_a_gradient_far_longer_than_its_running_mean():
    """Twenty gradients of norm 1 (running mean 1), then one of norm 100: SOAP steps as if
    it had been given that gradient at norm grad_clip = 2; without the guard it does not."""
    grad, blocks, theta0 = _matrix_problem()
    g = np.random.default_rng(4)
    unit = [v / np.linalg.norm(v) for v in g.standard_normal((21, theta0.size))]
    thetas = []
    for grad_clip, last in [(2.0, 100 * unit[-1]), (2.0, 2 * unit[-1]), (None, 100 * unit[-1])]:
        opt, theta = SOAP(lr=0.01, matrices=blocks, every=3, grad_clip=grad_clip), theta0.copy()
        for v in unit[:-1]:
            opt.step(theta, v)
        opt.step(theta, last)
        thetas.append(theta)
    assert np.allclose(thetas[0], thetas[1], rtol=0, atol=1e-12)
    assert np.abs(thetas[2] - thetas[0]).max() > 1e-4
    state = opt.state_dict()
    assert "gnorm" not in state and "gnorm" in SOAP(matrices=blocks).load_state_dict(
        dict(state, gnorm=np.ones(1)))._state


def test_soap_second_moment_decay_is_short_for_the_first_steps():
    """early_b2 = (b, T): for T steps SOAP is SOAP with betas (0.9, b); after them the decay
    is betas[1], and the bias correction stays one over the weight the running mean has
    gathered (w_t = b_t w_(t-1) + 1 - b_t)."""
    grad, blocks, theta0 = _matrix_problem()
    T = 6
    early = SOAP(lr=0.01, matrices=blocks, every=3, early_b2=(0.9, T))
    plain = SOAP(lr=0.01, matrices=blocks, every=3, betas=(0.9, 0.9), early_b2=None)
    a, b = theta0.copy(), theta0.copy()
    for t in range(1, 2 * T + 1):
        early.step(a, grad(a))
        plain.step(b, grad(b))
        if t == T:
            assert np.array_equal(a, b)
    assert np.abs(a - b).max() > 1e-6
    w = 0.0
    for t in range(1, 4 * T):
        b_t, c2 = early._second_decay(t)
        assert b_t == (0.9 if t <= T else 0.999)
        w = b_t * w + 1.0 - b_t
        assert c2 == pytest.approx(1.0 / w, rel=1e-12)


def test_soap_converges_and_its_state_round_trip_continues_identically():
    grad, blocks, theta = _matrix_problem()
    opt = SOAP(lr=0.05, matrices=blocks, every=3)
    f0 = np.abs(grad(theta)).max()
    for _ in range(7):
        opt.step(theta, grad(theta))
    twin = SOAP(lr=0.05, matrices=blocks, every=3).load_state_dict(opt.state_dict())
    copy = theta.copy()
    for _ in range(200):                      # across many new bases
        opt.step(theta, grad(theta))
        twin.step(copy, grad(copy))
    assert np.array_equal(theta, copy) and twin.t == opt.t == 207
    assert np.abs(grad(theta)).max() < 1e-3 * f0
    with pytest.raises(ValueError, match="lacks"):
        SOAP(lr=0.05, matrices=blocks * 2).load_state_dict(opt.state_dict())
    with pytest.raises(ValueError, match="'Adam'"):
        SOAP(lr=0.05, matrices=blocks).load_state_dict(Adam().state_dict())
    with pytest.raises(ValueError, match=r"L0 has shape \(1, 6, 6\), expected \(1, 5, 5\)"):
        SOAP(lr=0.05, matrices=[(slice(0, 30), (5, 6))]).load_state_dict(opt.state_dict())


def test_soap_trains_a_network_through_make_optimizer():
    net = ResidualMLP(width=16, depth=2, seed=0)
    x = np.random.default_rng(1).standard_normal((128, 3))
    target = np.sin(2 * x)

    def loss(y, JD, sl):
        r = y - target[sl]
        return (r ** 2).sum() / len(x), 2 * r / len(x), None

    ps = net.param_slices()
    opt = make_optimizer("soap", 1e-2, matrices=[ps["W1"], ps["W2"]])
    first = net.value_and_grad(x, loss, order=0)[0]
    for _ in range(150):
        opt.step(net.theta, net.value_and_grad(x, loss, order=0)[1])
    assert net.value_and_grad(x, loss, order=0)[0] < 0.05 * first


@pytest.mark.parametrize("options, match", [
    ({"clip": 0.0}, "clip must be finite and > 0"),
    ({"clip": float("nan")}, "clip must be finite"),
    ({"every": 0}, "every"),
    ({"betas": (0.9, 1.0)}, r"betas must lie in \[0, 1\)"),
    ({"early_b2": (1.0, 10)}, r"early_b2's decay must lie in \[0, 1\)"),
    ({"early_b2": (0.95, 0)}, "early_b2's steps"),
    ({"early_b2": 0.95}, r"early_b2 must be a pair \(decay, steps\) or None"),
])
def test_soap_bad_constants_are_named(options, match):
    with pytest.raises(ValueError, match=match):
        SOAP(**options)


@pytest.mark.parametrize("blocks, match", [
    ([(slice(0, 30), (6,))], r"shape must be \(m, n\)"),
    ([(slice(0, 31), (6, 5))], "holds 31 numbers"),
    ([(slice(None, 30), (6, 5))], "slice with a start"),
    ([(slice(0, 30, 2), (6, 5))], "slice with a start"),
    ([30], r"must be \(slice, shape\)"),
])
def test_soap_bad_blocks_are_named(blocks, match):
    with pytest.raises(ValueError, match=match):
        SOAP(matrices=blocks)


def test_soap_blocks_outside_theta_or_overlapping():
    with pytest.raises(ShapeError, match="inside theta of length 20"):
        SOAP(matrices=[(slice(0, 30), (6, 5))]).step(np.zeros(20), np.ones(20))
    both = [(slice(0, 30), (6, 5)), (slice(20, 50), (5, 6))]
    with pytest.raises(ShapeError, match="overlap"):
        SOAP(matrices=both).step(np.zeros(60), np.ones(60))
    opt = SOAP(matrices=[(slice(0, 30), (6, 5))])
    opt.step(np.zeros(40), np.ones(40))
    with pytest.raises(ShapeError, match="new optimiser"):
        opt.step(np.zeros(41), np.ones(41))
