"""Parameter layout and initialisation of :class:`~sns_np.nn.mlp.ResidualMLP` (private).

All parameters live in one flat vector ``theta``, in this order (d = in_dim, o = out_dim,
w = width; the biases have length 0 when the network has none)::

    W0 (w, d)    b0 (w,)    W1 (depth, w, w)    b1 (depth, w)
    W2 (depth, w, w)    b2 (depth, w)    W3 (o, w)    b3 (o,)

The network's weight arrays are views into that vector, so that ``pack``/``unpack`` connect
directly to ``scipy.optimize`` and the optimisers of :mod:`sns_np.nn.optim`.
"""

from __future__ import annotations

import numpy as np

#: the parameter arrays, in their order in theta
NAMES = ("W0", "b0", "W1", "b1", "W2", "b2", "W3", "b3")


def count_params(in_dim, out_dim, width, depth, bias=False) -> int:
    """``w d + 2 depth w^2 + o w``, plus ``w + 2 depth w + o`` biases, in exact integers."""
    d, o, w, depth = (int(v) for v in (in_dim, out_dim, width, depth))
    n = w * d + 2 * depth * w * w + o * w
    return n + (w + 2 * depth * w + o if bias else 0)


def layout(in_dim, out_dim, width, depth, bias):
    """``(shapes, offsets, n_params)``: name -> shape, name -> (start, stop) in theta."""
    d, w, o = in_dim, width, out_dim
    nb = 1 if bias else 0
    shapes = {
        "W0": (w, d), "b0": (w * nb,),
        "W1": (depth, w, w), "b1": (depth, w * nb),
        "W2": (depth, w, w), "b2": (depth, w * nb),
        "W3": (o, w), "b3": (o * nb,),
    }
    offsets = {}
    off = 0
    for name in NAMES:
        size = int(np.prod(shapes[name]))
        offsets[name] = (off, off + size)
        off += size
    return shapes, offsets, off


def initialize(net, g):
    """Draw ``net``'s parameters from the generator ``g`` (the scheme: ResidualMLP's Notes).

    One draw per weight array, in the order W0, W1, W2, W3; biases are set to zero.
    """
    w, d, depth = net.width, net.in_dim, net.depth
    net.W0[...] = g.standard_normal(net.W0.shape) * (net.input_scale / np.sqrt(d))
    net.W1[...] = g.standard_normal(net.W1.shape) * np.sqrt(2.0 / w)
    net.W2[...] = g.standard_normal(net.W2.shape) / np.sqrt(w * max(depth, 1))
    net.W3[...] = g.standard_normal(net.W3.shape) * (1e-2 / np.sqrt(w))
    for b in ("b0", "b1", "b2", "b3"):
        getattr(net, b)[...] = 0.0
