"""Refits of a surface network's read-out layer during a fit: the ridge read-out of the
initial features, and Levenberg-Marquardt steps on the full position + normal loss."""

from __future__ import annotations

import numpy as np

from ..geometry import tangent_frame
from ..nn.mlp import ResidualMLP
from .losses import normals_from_tangents


def _feature_jet(net, p, R):
    """The last hidden layer and its derivatives along the frame: h (n, w), hD (n, w, 2)."""
    f = ResidualMLP.zeros(net.in_dim, net.width, net.width, net.depth, net.bias,
                          dtype=np.float64)
    src = net.astype(np.float64)
    for name, (sl, _) in src.param_slices().items():
        if name not in ("W3", "b3"):
            f.theta[sl] = src.theta[sl]
    f.W3[...] = np.eye(net.width)
    return f.jet(p, order=1, directions=R)


def _cross_matrix(a):
    """[a]_x with [a]_x b = a x b, for rows a (n, 3) -> (n, 3, 3)."""
    z = np.zeros(len(a))
    return np.stack([np.stack([z, -a[:, 2], a[:, 1]], 1), np.stack([a[:, 2], z, -a[:, 0]], 1),
                     np.stack([-a[:, 1], a[:, 0], z], 1)], 1)


def _gauss_newton_readout(net, target, rng, normal_weight, tangent_weight=1.0, n=4096,
                          iters=2, rel_reg=1e-6):
    """Levenberg-Marquardt steps on the output layer for the full position + normal loss.

    The loss is quadratic in ``W3`` through the positions and, through the normals
    ``n = (W3 h_u) x (W3 h_v) / |...|``, nearly so: linearising the normals gives a
    768-unknown least-squares problem whose solution is the best read-out of the current
    features (variable projection). A step is kept only if it lowers the loss on its sample.
    """
    p, q, nt = target.sample(n, rng)
    R = tangent_frame(p)
    h, hD = _feature_jet(net, p, R)
    w = net.width
    W = net.W3.astype(np.float64).copy()
    sw = np.sqrt(normal_weight)
    Mh = np.einsum("ki,kj->kij", nt, nt)
    Mh = Mh + np.sqrt(tangent_weight) * (np.eye(3) - Mh)

    def residuals(W):
        y = h @ W.T + (net.b3.astype(np.float64) if net.bias else 0.0)
        Su, Sv = hD[:, :, 0] @ W.T, hD[:, :, 1] @ W.T
        nrm, c = normals_from_tangents(Su, Sv, degenerate="zero")
        rp = np.einsum("kab,kb->ka", Mh, y - q)
        return rp, sw * (nrm - nt), Su, Sv, nrm, c

    def loss(rp, rn):
        return float((rp ** 2).sum() + (rn ** 2).sum()) / n

    rp, rn, Su, Sv, nrm, c = residuals(W)
    cur = loss(rp, rn)
    lam = None
    for _ in range(iters):
        # position block: d rp_a / dW_ij = Mh_ai h_j ; normal block as in losses.py
        Jp = np.einsum("kai,kj->kaij", Mh, h).reshape(n * 3, 3 * w)
        P = (np.eye(3) - np.einsum("ka,kb->kab", nrm, nrm)) / c[:, None, None]
        A = -np.einsum("kab,kbi->kai", P, _cross_matrix(Sv))
        B = np.einsum("kab,kbi->kai", P, _cross_matrix(Su))
        Jn = sw * (np.einsum("kai,kj->kaij", A, hD[:, :, 0])
                   + np.einsum("kai,kj->kaij", B, hD[:, :, 1])).reshape(n * 3, 3 * w)
        G = Jp.T @ Jp + Jn.T @ Jn
        g = Jp.T @ rp.ravel() + Jn.T @ rn.ravel()
        if lam is None:
            lam = rel_reg * np.trace(G) / G.shape[0]
        for _try in range(6):
            Gd = G.copy()
            Gd[np.diag_indices_from(Gd)] += lam
            Wn = W - np.linalg.solve(Gd, g).reshape(3, w)
            out = residuals(Wn)
            new = loss(out[0], out[1])
            if np.isfinite(new) and new < cur:
                W, cur, lam = Wn, new, lam / 3
                rp, rn, Su, Sv, nrm, c = out
                break
            lam *= 10
        else:
            break
    net.W3[...] = W.astype(net.dtype)
    return cur


def _ridge_readout(net, target, rng, n=8192, rel_reg=1e-6):
    """Set W3 (and b3) to the regularised least-squares read-out of the initial features."""
    p, q, _ = target.sample(n, rng)
    net.fit_readout(p, q, rel_reg=rel_reg)

