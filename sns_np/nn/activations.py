"""Softplus and its derivatives, in plain NumPy: the readable reference for the fused kernels.

The network uses softplus with beta = 1,

    s(z)    = log(1 + e^z)            (softplus)
    s'(z)   = 1 / (1 + e^-z)          (the logistic sigmoid, sig)
    s''(z)  = sig (1 - sig)
    s'''(z) = sig (1 - sig) (1 - 2 sig)

each written in a form that never overflows: with e = exp(-|z|) in (0, 1],
``s(z) = max(z, 0) + log1p(e)`` and ``sig = 1 / (1 + e)`` for z >= 0, ``e / (1 + e)`` otherwise.

The Numba kernels in :mod:`sns_np.nn._kernels` compute the same values with their own
vectorisable exp/log1p (tests compare them with these functions to round-off).

Jet rules (DESIGN.md): for a pre-activation with value z, first-order streams z_a and
second-order streams z_ab, the activation a = s(z) has

    a    = s(z)
    a_a  = s'(z) z_a
    a_ab = s''(z) z_a z_b + s'(z) z_ab
"""

from __future__ import annotations

import numpy as np

__all__ = ["softplus", "sigmoid", "softplus_derivatives", "ACTIVATIONS"]


def softplus(z):
    """s(z) = log(1 + e^z), overflow-free.

    Examples
    --------
    >>> softplus(np.array([-800.0, 0.0, 800.0]))                   # no overflow
    array([0.00000000e+00, 6.93147181e-01, 8.00000000e+02])
    """
    z = np.asarray(z)
    return np.maximum(z, 0) + np.log1p(np.exp(-np.abs(z)))


def sigmoid(z):
    """s'(z) = 1 / (1 + e^-z), overflow-free.

    Examples
    --------
    >>> sigmoid(np.array([-800.0, 0.0, 800.0]))
    array([0. , 0.5, 1. ])
    """
    z = np.asarray(z)
    e = np.exp(-np.abs(z))
    return np.where(z >= 0, 1.0, e) / (1.0 + e)


def softplus_derivatives(z, order: int = 3):
    """Return (s, s', s'', s''') of softplus at z, up to ``order`` derivatives."""
    sig = sigmoid(z)
    out = [softplus(z), sig]
    if order >= 2:
        out.append(sig * (1 - sig))
    if order >= 3:
        out.append(sig * (1 - sig) * (1 - 2 * sig))
    return tuple(out[: order + 1])


#: registry: name -> function returning (value, first, second, third derivative)
ACTIVATIONS = {"softplus": softplus_derivatives}
