"""The surface-map and field protocols of DESIGN.md, and validated calls into them.

A **surface map** is any object with ``jet(p, order)``:

* order 0 -> ``y`` (n, 3)
* order 1 -> ``(y, J)`` with ``J[k, i, a] = dS_i / dx_a``, shape (n, 3, 3)
* order 2 -> ``(y, J, D2)`` with ``D2[k, i, a, b] = d2 S_i / dx_a dx_b``, shape (n, 3, 3, 3)

Derivatives are ambient (with respect to x in R^3). A map may also offer **directional jets**,
``jet(p, order, directions=D, second=k)`` with per-point directions ``D`` (n, 3, m): order 1
returns ``(y, JD)`` with ``JD = J @ D`` (n, 3, m); order 2 also returns ``D2D`` (n, 3, k, k),
the second derivatives along every pair of the first ``k`` columns of ``D`` (default ``k = m``).
Geometry uses them when offered (:func:`offers_directions`) and falls back to full jets.

A **field** is any object with ``jet(p, order)`` returning the value (n,), the gradient (n, 3)
and the Hessian (n, 3, 3), ambient in R^3.

The functions here call a map or field, check every returned shape and value, and raise
:class:`~sns_np.errors.ShapeError` naming the offending map and array otherwise, so that a
broken user map fails loudly instead of producing silent garbage downstream.
"""

from __future__ import annotations

import inspect

import numpy as np

from ._validation import check_order
from .errors import ShapeError

__all__ = [
    "offers_directions",
    "surface_jet",
    "directional_jet",
    "field_jet",
    "chunk_slices",
]


def offers_directions(obj) -> bool:
    """True if ``obj.jet`` accepts ``directions=`` (and ``second=``) keyword arguments.

    Examples
    --------
    >>> from sns_np.nn import ResidualMLP
    >>> from sns_np.shapes import Sphere
    >>> offers_directions(ResidualMLP(width=4, depth=1)), offers_directions(Sphere())
    (True, False)
    """
    jet = getattr(obj, "jet", None)
    if jet is None:
        return False
    try:
        params = inspect.signature(jet).parameters
    except (TypeError, ValueError):
        return False
    return "directions" in params and "second" in params


def chunk_slices(n: int, chunk: int):
    """Yield slices covering ``range(n)`` in blocks of at most ``chunk``.

    Examples
    --------
    >>> list(chunk_slices(5, 2))
    [slice(0, 2, None), slice(2, 4, None), slice(4, 5, None)]
    """
    chunk = max(int(chunk), 1)
    for start in range(0, n, chunk):
        yield slice(start, min(start + chunk, n))


def _name(obj) -> str:
    return type(obj).__name__


def _check(arr, shape, what, obj) -> np.ndarray:
    arr = np.asarray(arr)
    if arr.shape != shape:
        raise ShapeError(
            f"{_name(obj)}.jet returned {what} of shape {arr.shape}; expected {shape}"
        )
    if not np.all(np.isfinite(arr)):
        k = int(np.argwhere(~np.isfinite(arr.reshape(shape[0], -1)))[0, 0])
        raise ShapeError(
            f"{_name(obj)}.jet returned non-finite {what} (first at point {k}); the map "
            f"must be finite and smooth on the unit sphere"
        )
    return arr


def _require_jet(obj, kind):
    if not callable(getattr(obj, "jet", None)):
        raise TypeError(f"{kind} must have a jet(p, order) method, got {_name(obj)}")


def surface_jet(surface, p: np.ndarray, order: int):
    """Call ``surface.jet(p, order)`` and validate shapes and finiteness.

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array
    order : int, 0, 1 or 2

    Returns
    -------
    y or (y, J) or (y, J, D2) as in the surface-map protocol, as float64 arrays.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> y, J = surface_jet(Sphere(2.0), np.array([[0.0, 0.0, 1.0]]), 1)
    >>> y, J.shape
    (array([[0., 0., 2.]]), (1, 3, 3))
    >>> class Broken:
    ...     def jet(self, p, order=0):
    ...         return np.zeros((len(p), 2))
    >>> surface_jet(Broken(), np.zeros((4, 3)), 0)
    Traceback (most recent call last):
        ...
    sns_np.errors.ShapeError: Broken.jet returned y of shape (4, 2); expected (4, 3)
    """
    _require_jet(surface, "surface")
    order = check_order(order)
    n = p.shape[0]
    out = surface.jet(p, order)
    if order == 0:
        if isinstance(out, tuple):
            out = out[0]
        return _check(out, (n, 3), "y", surface).astype(np.float64, copy=False)
    if not isinstance(out, tuple) or len(out) != order + 1:
        raise ShapeError(
            f"{_name(surface)}.jet(p, {order}) must return a tuple of {order + 1} arrays"
        )
    shapes = [(n, 3), (n, 3, 3), (n, 3, 3, 3)]
    names = ["y", "J", "D2"]
    return tuple(
        _check(a, s, w, surface).astype(np.float64, copy=False)
        for a, s, w in zip(out, shapes, names)
    )


def directional_jet(surface, p: np.ndarray, order: int, D: np.ndarray, second: int | None = None):
    """Derivatives of a surface map along per-point directions.

    Uses the map's own directional jet when it offers one, otherwise contracts the full jet:
    ``JD = J @ D`` and ``D2D[k, i, a, b] = D2[k, i] : (D[k, :, a], D[k, :, b])``.

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array
    order : int, 1 or 2
    D : (n, 3, m) float array of directions
    second : int, optional
        Second derivatives are returned along pairs of the first ``second`` columns of ``D``
        (default: all ``m``).

    Returns
    -------
    (y, JD) or (y, JD, D2D) with shapes (n, 3), (n, 3, m), (n, 3, k, k).

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> from sns_np.geometry import tangent_frame
    >>> p = np.array([[0.0, 0.0, 1.0]])
    >>> D = np.concatenate([tangent_frame(p), p[:, :, None]], axis=2)   # [e_u, e_v, p]
    >>> y, JD, D2D = directional_jet(Ellipsoid(1.0, 2.0, 3.0), p, 2, D, second=2)
    >>> JD.shape, D2D.shape
    ((1, 3, 3), (1, 3, 2, 2))
    """
    order = check_order(order, (1, 2))
    n = p.shape[0]
    D = np.asarray(D, dtype=np.float64)
    if D.ndim != 3 or D.shape[0] != n or D.shape[1] != 3:
        raise ShapeError(f"directions must have shape ({n}, 3, m), got {D.shape}")
    m = D.shape[2]
    k = m if second is None else int(second)
    if not 0 <= k <= m:
        raise ValueError(f"second must be between 0 and {m}, got {second}")
    if offers_directions(surface):
        if order == 2:
            out = surface.jet(p, order, directions=D, second=k)
        else:
            out = surface.jet(p, order, directions=D)
        if not isinstance(out, tuple) or len(out) != order + 1:
            raise ShapeError(
                f"{_name(surface)}.jet(p, {order}, directions=...) must return "
                f"{order + 1} arrays"
            )
        shapes = [(n, 3), (n, 3, m), (n, 3, k, k)]
        return tuple(
            _check(a, s, w, surface).astype(np.float64, copy=False)
            for a, s, w in zip(out, shapes, ["y", "JD", "D2D"])
        )
    full = surface_jet(surface, p, order)
    y, J = full[0], full[1]
    JD = np.einsum("kia,kam->kim", J, D)
    if order == 1:
        return y, JD
    Dk = D[:, :, :k]
    D2D = np.einsum("kiab,kap,kbq->kipq", full[2], Dk, Dk, optimize=True)
    return y, JD, D2D


def field_jet(field, p: np.ndarray, order: int):
    """Call ``field.jet(p, order)`` and validate: value (n,), gradient (n, 3), Hessian (n, 3, 3).

    Examples
    --------
    >>> from sns_np.shapes import SphericalHarmonic
    >>> v, g = field_jet(SphericalHarmonic(1, 0), np.array([[0.0, 0.0, 1.0]]), 1)
    >>> round(float(v[0]), 6), g.shape
    (0.488603, (1, 3))
    """
    _require_jet(field, "field")
    order = check_order(order)
    n = p.shape[0]
    out = field.jet(p, order)
    if order == 0:
        if isinstance(out, tuple):
            out = out[0]
        return _check(out, (n,), "value", field).astype(np.float64, copy=False)
    if not isinstance(out, tuple) or len(out) != order + 1:
        raise ShapeError(f"{_name(field)}.jet(p, {order}) must return {order + 1} arrays")
    shapes = [(n,), (n, 3), (n, 3, 3)]
    return tuple(
        _check(a, s, w, field).astype(np.float64, copy=False)
        for a, s, w in zip(out, shapes, ["value", "gradient", "Hessian"])
    )
