"""The least-squares fit of the read-out layer of a ResidualMLP (private).

The network is linear in its read-out, ``y = h W3^T + b3`` with ``h`` the last hidden layer:
with the features ``F = [h, 1]`` (the column of ones only with biases), point weights
``w_k`` and the read-out ``T = [W3, b3]^T``, the fit solves the normal equations

    (F^T diag(w) F + lam I) T = F^T diag(w) r,      lam = rel_reg * trace(G) / size(G)

(``G`` the Gram matrix on the left, ``lam`` a relative Tikhonov term), for the targets ``r``
(replacing the read-out) or the residuals ``target - current`` (adding a change to it). A
scalar read-out ``g = scale * mean_o y_o`` (a field's value) is fitted as one change shared by
every output row. :meth:`sns_np.nn.ResidualMLP.fit_readout` validates and calls :func:`fit`.
"""

from __future__ import annotations

import numpy as np


def fit(net, x, target, weights, rel_reg, increment, scale, current):
    """Fit the read-out of ``net`` at checked x; the solution T (see the module docstring).

    T is (width (+1), out_dim), or (width (+1),) for a scalar target (n,). When T is not
    finite the network is left unchanged.
    """
    n, w, o = x.shape[0], net.width, net.out_dim
    scalar = target.ndim == 1
    feats = net.features(x).astype(np.float64)
    if net.bias:
        feats = np.hstack([feats, np.ones((n, 1))])
    if not increment:
        rhs = target
    elif current is not None:
        rhs = target - current
    else:
        y = feats[:, :w] @ net.W3.T.astype(np.float64)
        if net.bias:
            y = y + net.b3
        rhs = target - (scale / o * y.sum(axis=1) if scalar else y)
    if weights is not None:
        sw = np.sqrt(weights)
        feats, rhs = feats * sw[:, None], rhs * (sw[:, None] if rhs.ndim == 2 else sw)
    G = feats.T @ feats
    G[np.diag_indices_from(G)] += rel_reg * max(np.trace(G) / G.shape[0], 1e-300)
    T = np.linalg.solve(G, feats.T @ np.asarray(rhs, dtype=np.float64))
    if scalar:
        T = T / scale
    if not np.all(np.isfinite(T)):
        return T
    if scalar:       # the same change in every output row: g changes by scale * [h, 1] . T
        net.W3[...] += T[:w]
        if net.bias:
            net.b3[...] += T[w]
    elif increment:
        net.W3[...] += T[:w].T
        if net.bias:
            net.b3[...] += T[w]
    else:
        net.W3[...] = T[:w].T
        if net.bias:
            net.b3[...] = T[w]
    return T
