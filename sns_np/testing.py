"""Derivative checks by central differences, used by the test-suite of every module.

Each check compares an analytic derivative with a central difference of the quantity one order
lower, in float64, and returns the relative error::

    err = max |analytic - numeric| / max(max |numeric|, floor)

so a test can assert ``err < tol``. With ``richardson=True`` the difference quotient is
extrapolated from steps h and h/2, ``(4 D(h/2) - D(h)) / 3``, which cancels the O(h^2) term and
lets checks reach 1e-9 instead of 1e-6.

Functions
---------
check_jet          J and D2 of ``obj.jet`` against differences of its value and J
check_directional_jet   a directional jet against the full jet and against differences
check_gradient     a (loss, gradient) function against differences, all parameters or directions
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ._validation import as_generator

__all__ = ["relative_error", "central_difference", "check_jet", "check_directional_jet",
           "check_gradient"]


def relative_error(analytic, numeric, floor: float = 1e-12) -> float:
    """``max |analytic - numeric| / max(max |numeric|, floor)``.

    Examples
    --------
    >>> round(relative_error(np.array([1.0, 2.0]), np.array([1.0, 2.002])), 6)   # 0.002 / 2.002
    0.000999
    """
    a = np.asarray(analytic, dtype=np.float64)
    b = np.asarray(numeric, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: analytic {a.shape} vs numeric {b.shape}")
    if a.size == 0:
        return 0.0
    scale = max(float(np.max(np.abs(b))), floor)
    return float(np.max(np.abs(a - b))) / scale


def central_difference(f: Callable, x: np.ndarray, v: np.ndarray, h: float,
                       richardson: bool = False):
    """Directional derivative of ``f`` at ``x`` along ``v`` by central differences.

    ``f`` maps an array shaped like ``x`` to an array (or tuple of arrays); ``v`` has the shape
    of ``x``. Returns the difference quotient with the structure of ``f(x)``.

    Examples
    --------
    >>> x = np.array([0.5])
    >>> d = central_difference(np.sin, x, np.ones(1), 1e-4, richardson=True)
    >>> bool(abs(d[0] - np.cos(0.5)) < 1e-12)
    True
    """

    def quotient(step):
        fp, fm = f(x + step * v), f(x - step * v)
        if isinstance(fp, tuple):
            return tuple((a - b) / (2 * step) for a, b in zip(fp, fm))
        return (fp - fm) / (2 * step)

    d1 = quotient(h)
    if not richardson:
        return d1
    d2 = quotient(h / 2)
    if isinstance(d1, tuple):
        return tuple((4 * b - a) / 3 for a, b in zip(d1, d2))
    return (4 * d2 - d1) / 3


def _jet_out(obj, x, order, **kw):
    out = obj.jet(x, order, **kw)
    if order == 0 and isinstance(out, tuple):
        out = out[0]
    return out


def check_jet(obj, x, order: int = 2, h: float = 1e-5, richardson: bool = False) -> dict:
    """Compare the analytic derivatives of ``obj.jet`` with central differences.

    ``J[..., a]`` is compared with the difference of the value along ``e_a``, and (order 2)
    ``D2[..., a, b]`` with the difference of ``J[..., a]`` along ``e_b``; the symmetry of D2 is
    checked as well. Works for surface maps (value (n, o)) and fields (value (n,)).

    Parameters
    ----------
    obj : object with ``jet(x, order)``
    x : (n, 3) float array of evaluation points
    order : int, 1 or 2
    h : float, difference step
    richardson : bool, extrapolate from h and h/2

    Returns
    -------
    dict with keys ``"J"`` and (order 2) ``"D2"``, ``"D2_symmetry"``: relative errors.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> p = np.array([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0]])
    >>> err = check_jet(Ellipsoid(1.0, 2.0, 3.0), p, order=2)
    >>> sorted(err), bool(err["J"] < 1e-8)
    (['D2', 'D2_symmetry', 'J'], True)
    """
    x = np.asarray(x, dtype=np.float64)
    n, dim = x.shape
    out = obj.jet(x, order)
    J = np.asarray(out[1])
    report = {}
    Jfd = np.empty_like(J)
    for a in range(dim):
        e = np.zeros_like(x)
        e[:, a] = 1.0
        Jfd[..., a] = central_difference(lambda z: _jet_out(obj, z, 0), x, e, h, richardson)
    report["J"] = relative_error(J, Jfd)
    if order >= 2:
        D2 = np.asarray(out[2])
        D2fd = np.empty_like(D2)
        for b in range(dim):
            e = np.zeros_like(x)
            e[:, b] = 1.0
            dJ = central_difference(lambda z: np.asarray(obj.jet(z, 1)[1]), x, e, h, richardson)
            D2fd[..., :, b] = dJ
        report["D2"] = relative_error(D2, D2fd)
        report["D2_symmetry"] = relative_error(D2, np.swapaxes(D2, -1, -2), floor=1.0)
    return report


def check_directional_jet(obj, x, D, order: int = 2, second: int | None = None,
                          h: float = 1e-5, richardson: bool = False) -> dict:
    """Check a directional jet against the full jet and against differences along ``D``.

    Returns relative errors ``"JD_vs_full"``, ``"JD_vs_fd"`` and (order 2) ``"D2D_vs_full"``,
    ``"D2D_vs_fd"``.

    Examples
    --------
    >>> from sns_np.nn import ResidualMLP
    >>> net = ResidualMLP(width=8, depth=1, seed=0)
    >>> x = np.array([[0.6, 0.0, 0.8]])
    >>> D = np.random.default_rng(0).standard_normal((1, 3, 3))
    >>> err = check_directional_jet(net, x, D, order=2, second=2)
    >>> bool(max(err.values()) < 1e-6)
    True
    """
    x = np.asarray(x, dtype=np.float64)
    D = np.asarray(D, dtype=np.float64)
    m = D.shape[2]
    k = m if second is None else second
    out = obj.jet(x, order, directions=D, second=k)
    full = obj.jet(x, order)
    report = {}
    JD = out[1]
    report["JD_vs_full"] = relative_error(JD, np.einsum("k...a,kam->k...m", full[1], D))
    JDfd = np.stack(
        [central_difference(lambda z: _jet_out(obj, z, 0), x, D[:, :, a], h, richardson)
         for a in range(m)], axis=-1)
    report["JD_vs_fd"] = relative_error(JD, JDfd)
    if order >= 2 and k == 0:
        report["D2D_vs_full"] = report["D2D_vs_fd"] = 0.0 if out[2].size == 0 else np.inf
    elif order >= 2:
        D2D = out[2]
        Dk = D[:, :, :k]
        report["D2D_vs_full"] = relative_error(
            D2D, np.einsum("k...ab,kap,kbq->k...pq", full[2], Dk, Dk, optimize=True))
        cols = []
        for b in range(k):
            dJ = central_difference(lambda z: np.asarray(obj.jet(z, 1)[1]), x, D[:, :, b], h,
                                    richardson)
            cols.append(np.einsum("k...a,kap->k...p", dJ, Dk))
        report["D2D_vs_fd"] = relative_error(D2D, np.stack(cols, axis=-1))
    return report


def check_gradient(fun: Callable, theta, h: float = 1e-6, n_directions: int | None = None,
                   rng=None, richardson: bool = False) -> float:
    """Check ``fun(theta) -> (loss, grad)`` against central differences of the loss.

    With ``n_directions=None`` every parameter is differenced (use for tiny models); otherwise
    the directional derivative ``grad . v`` is compared along ``n_directions`` random unit
    vectors ``v`` (seeded by ``rng``), as HIPS/autograd does for large ones.

    Returns
    -------
    float
        The relative error over all compared derivatives.

    Examples
    --------
    >>> A = np.array([[2.0, 1.0], [1.0, 3.0]])
    >>> fun = lambda t: (0.5 * t @ A @ t, A @ t)          # loss and its gradient
    >>> bool(check_gradient(fun, np.array([1.0, -1.0])) < 1e-8)
    True
    >>> bool(check_gradient(fun, np.array([1.0, -1.0]), n_directions=4, rng=0) < 1e-8)
    True
    """
    theta = np.asarray(theta, dtype=np.float64).copy()
    _, g = fun(theta)
    g = np.asarray(g, dtype=np.float64)
    if g.shape != theta.shape:
        raise ValueError(f"gradient has shape {g.shape}, expected {theta.shape}")

    def loss(t):
        return np.asarray(fun(t)[0], dtype=np.float64)

    if n_directions is None:
        num = np.empty_like(theta)
        for i in range(theta.size):
            e = np.zeros_like(theta)
            e[i] = 1.0
            num[i] = central_difference(loss, theta, e, h, richardson)
        return relative_error(g, num)
    gen = as_generator(rng)
    ana, num = [], []
    for _ in range(int(n_directions)):
        v = gen.standard_normal(theta.shape)
        v /= np.linalg.norm(v)
        ana.append(float(g @ v))
        num.append(float(central_difference(loss, theta, v, h, richardson)))
    return relative_error(np.array(ana), np.array(num))
