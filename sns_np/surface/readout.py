"""Least-squares read-outs: the exact solve for a network's last (linear) layer.

Used by the fits that restart from a surface (:func:`sns_np.surface.fit_sdf`) and by the flows
(:mod:`sns_np.flows`), which refit a network after every step.
"""

from __future__ import annotations

import numpy as np

__all__ = ["lstsq_readout", "surface_readout"]


def lstsq_readout(features, residual, rel_reg=1e-10):
    """``delta`` (width, k) minimising ``|features delta - residual|^2`` (+ a tiny ridge)."""
    Phi = np.asarray(features, dtype=np.float64)
    G = Phi.T @ Phi
    G[np.diag_indices_from(G)] += rel_reg * max(np.trace(G) / G.shape[0], 1e-300)
    return np.linalg.solve(G, Phi.T @ np.asarray(residual, dtype=np.float64))


def surface_readout(net, p, q):
    """Set the read-out layer of a surface network to the least-squares fit of ``q`` at ``p``.

    The network is linear in ``W3`` (and ``b3``): ``y = h W3^T + b3``. One exact solve is a
    Gauss-Newton step in the last layer; a uniform scaling of the output (a shrinking sphere)
    is captured exactly.
    """
    Phi = net.features(p).astype(np.float64)
    if net.bias:
        Phi = np.hstack([Phi, np.ones((Phi.shape[0], 1))])
    y = Phi[:, :net.width] @ net.W3.T.astype(np.float64)
    if net.bias:
        y = y + net.b3
    d = lstsq_readout(Phi, q - y)
    net.W3[...] += d[:net.width].T
    if net.bias:
        net.b3[...] += d[net.width]
