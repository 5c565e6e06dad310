"""Shared private helpers of sns_np.geometry: chart jets, degeneracy checks, option checks."""

from __future__ import annotations

import numpy as np

from .._validation import check_positive_float, check_positive_int
from ..errors import DegenerateMapError
from ..protocol import directional_jet
from .forms import first_fundamental_form_from_jets, metric_conditioning

#: points per chunk: bounds memory (an order-2 full jet of 65536 points is ~14 MB)
CHUNK = 65536
#: default threshold on sigma_min / sigma_max of J R (and of the 3 x 3 J where needed)
DEGENERATE_TOL = 1e-8


def check_options(chunk, tol):
    return (check_positive_int(chunk, "chunk"),
            check_positive_float(tol, "tol", allow_zero=True))


def chart_jets(surface, p, R, order):
    """Directional jets along the frame: ``y``, ``JR`` and (order 2) ``Jp``, ``S2``.

    Order 1 propagates 2 directions ``[e_u, e_v]``. Order 2 propagates ``D = [e_u, e_v, p]``
    with second derivatives along the pairs of ``e_u, e_v`` only: 3 first-order and 3 distinct
    second-order streams plus the value (7 instead of 10 for a full jet).
    """
    if order == 1:
        y, JR = directional_jet(surface, p, 1, R)
        return y, JR
    D = np.concatenate([R, p[:, :, None]], axis=2)
    y, JD, D2D = directional_jet(surface, p, 2, D, second=2)
    Jp = JD[:, :, 2]
    S2 = D2D - Jp[:, :, None, None] * np.eye(2)
    return y, JD[:, :, :2], Jp, S2


def degenerate_mask(JR, tol):
    """True where ``sigma_min / sigma_max`` of ``J R`` is below ``tol`` (or not finite)."""
    c = metric_conditioning(first_fundamental_form_from_jets(JR))
    return ~(c > tol)


def raise_degenerate(bad, p, offset, what="the surface map", detail="J R has rank < 2"):
    """Raise :class:`DegenerateMapError` naming the first flagged point."""
    k = int(np.argmax(bad))
    raise DegenerateMapError(
        f"{what} is degenerate at point {offset + k} (p = {np.array2string(p[k], precision=6)}"
        f"): {detail}; {int(bad.sum())} point(s) of this chunk are affected")
