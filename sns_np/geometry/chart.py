"""Chart jets of a surface map, evaluated in chunks with one degeneracy check.

The one place where a surface map is called chunk by chunk along the sphere frame: geometry,
sampling and the flows all go through :func:`chart_jet_chunks` (or, for one chunk,
:func:`checked_chart_jets`), so the chunk size, the degeneracy test and its error message are
the same everywhere.

Degeneracy: a point is degenerate when ``sigma_min / sigma_max`` of ``J R`` (the 3 x 2 matrix
``[S_u, S_v]``) is below ``tol`` or not finite, i.e. ``det I`` is near zero and the normal,
the metric inverse and every curvature are undefined there.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_positive_float, check_positive_int
from ..errors import DegenerateMapError
from ..protocol import chunk_slices, directional_jet
from .forms import first_fundamental_form_from_jets, metric_conditioning
from .frame import _frame

__all__ = ["CHUNK", "DEGENERATE_TOL", "chart_jets", "degenerate_mask", "raise_degenerate",
           "checked_chart_jets", "chart_jet_chunks", "check_options"]

#: points per chunk: bounds memory (an order-2 full jet of 65536 points is ~14 MB)
CHUNK = 65536
#: default threshold on sigma_min / sigma_max of J R (and of the 3 x 3 J where needed)
DEGENERATE_TOL = 1e-8


def check_options(chunk, tol):
    """Validated ``(chunk, tol)``: a positive int and a non-negative float."""
    return (check_positive_int(chunk, "chunk"),
            check_positive_float(tol, "tol", allow_zero=True))


def chart_jets(surface, p, R, order):
    """Directional jets along the frame: ``y``, ``JR`` and (order 2) ``Jp``, ``S2``.

    Order 1 propagates 2 directions ``[e_u, e_v]``. Order 2 propagates ``D = [e_u, e_v, p]``
    with second derivatives along the pairs of ``e_u, e_v`` only: 3 first-order and 3 distinct
    second-order streams plus the value (7 instead of 10 for a full jet).

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array of unit vectors
    R : (n, 3, 2) float array, the frame of :func:`sns_np.geometry.tangent_frame` at ``p``
    order : {1, 2}

    Returns
    -------
    order 1: ``y`` (n, 3), ``JR`` (n, 3, 2); order 2: also ``Jp`` (n, 3) and ``S2``
    (n, 3, 2, 2), ``S_ab = D2[e_a, e_b] - delta_ab J p``

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> from sns_np.geometry import tangent_frame
    >>> p = np.array([[0.0, 0.0, 1.0]])
    >>> y, JR = chart_jets(Sphere(2.0), p, tangent_frame(p), 1)
    >>> JR[0].T @ JR[0]                                  # I = 4 Id on a sphere of radius 2
    array([[4., 0.],
           [0., 4.]])
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
    """True where ``sigma_min / sigma_max`` of ``J R`` is below ``tol`` (or not finite).

    Examples
    --------
    >>> JR = np.stack([np.eye(3)[:, :2], np.zeros((3, 2))])
    >>> degenerate_mask(JR, 1e-8)
    array([False,  True])
    """
    c = metric_conditioning(first_fundamental_form_from_jets(JR))
    return ~(c > tol)


def raise_degenerate(bad, p, offset, what="the surface map", detail="J R has rank < 2"):
    """Raise :class:`~sns_np.errors.DegenerateMapError` naming the first flagged point.

    ``bad`` (n,) bool marks the degenerate rows of the chunk ``p`` (n, 3), whose first row is
    point ``offset`` of the whole input.
    """
    k = int(np.argmax(bad))
    raise DegenerateMapError(
        f"{what} is degenerate at point {offset + k} (p = {np.array2string(p[k], precision=6)}"
        f"): {detail}; {int(bad.sum())} point(s) of this chunk are affected")


def checked_chart_jets(surface, p, R, order, tol=DEGENERATE_TOL, offset=0, detail=None):
    """:func:`chart_jets` of one chunk, raising where :func:`degenerate_mask` flags a point.

    ``R=None`` uses the frame of ``p``; ``offset`` is the index of ``p[0]`` in the caller's
    whole input (for the error message); ``detail`` replaces the message's reason.
    """
    out = chart_jets(surface, p, _frame(p) if R is None else R, order)
    bad = degenerate_mask(out[1], tol)
    if bad.any():
        raise_degenerate(bad, p, offset, **({} if detail is None else {"detail": detail}))
    return out


def chart_jet_chunks(surface, p, order, *, R=None, chunk=CHUNK, tol=DEGENERATE_TOL,
                     on_degenerate="raise", detail=None):
    """Chart jets of ``surface`` at ``p``, chunk by chunk: yields ``(sl, jets, bad)``.

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array of unit vectors (not checked here)
    order : {1, 2}, see :func:`chart_jets`
    R : (n, 3, 2) float array or None, the frame at ``p`` (``None``: computed per chunk)
    chunk : int, points per call of the map
    tol : float, the threshold of :func:`degenerate_mask`
    on_degenerate : {"raise", "flag"}
        ``"raise"``: :class:`~sns_np.errors.DegenerateMapError` at the first chunk with a
        degenerate point (naming its global index); ``"flag"``: yield the mask ``bad`` and let
        the caller decide.
    detail : str or None, the reason given in the error message

    Yields
    ------
    sl : slice of the chunk in ``p``
    jets : tuple, the return value of :func:`chart_jets` for ``p[sl]``
    bad : (len(p[sl]),) bool array (all False with ``"raise"``)

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> from sns_np.sampling import fibonacci_sphere
    >>> [(sl.start, jets[1].shape) for sl, jets, _ in
    ...  chart_jet_chunks(Sphere(), fibonacci_sphere(5), 1, chunk=3)]
    [(0, (3, 3, 2)), (3, (2, 3, 2))]
    """
    if on_degenerate not in ("raise", "flag"):
        raise ValueError(f"on_degenerate must be 'raise' or 'flag', got {on_degenerate!r}")
    for sl in chunk_slices(p.shape[0], chunk):
        ps = p[sl]
        jets = chart_jets(surface, ps, _frame(ps) if R is None else R[sl], order)
        bad = degenerate_mask(jets[1], tol)
        if on_degenerate == "raise" and bad.any():
            raise_degenerate(bad, ps, sl.start, **({} if detail is None else {"detail": detail}))
        yield sl, jets, bad
