"""Normals, fundamental forms, curvatures and principal directions of any surface map.

Everything follows DESIGN.md: ``n = S_u x S_v / |S_u x S_v|`` outward, ``I = (J R)^T (J R)``,
``II_ab = -n . S_ab`` with ``S_ab = D2[e_a, e_b] - delta_ab J p``, convex-positive curvature
(unit sphere ``H = K = 1``), ``H = (kmin + kmax) / 2``. See ``docs/geometry.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import SPHERE_TOL, check_choice
from .chart import CHUNK, DEGENERATE_TOL, chart_jet_chunks, check_options
from .forms import (
    area_element_from_jets,
    first_fundamental_form_from_jets,
    normals_from_jets,
    principal_from_jets,
    second_fundamental_form_from_jets,
)
from .frame import sphere_points

__all__ = [
    "DifferentialQuantities", "differential_quantities", "normals", "first_fundamental_form",
    "area_element", "second_fundamental_form", "mean_curvature", "gaussian_curvature",
    "principal_curvatures", "principal_directions",
]


@dataclass
class DifferentialQuantities:
    """Per-point differential geometry of a surface map (all arrays have n rows).

    Attributes
    ----------
    x : (n, 3) surface points ``S(p)``
    n : (n, 3) outward unit normals
    I, II : (n, 2, 2) first and second fundamental forms in the frame of ``tangent_frame(p)``
    H, K : (n,) mean and Gaussian curvature (convex positive; unit sphere ``H = K = 1``)
    kmin, kmax : (n,) principal curvatures, ``kmin <= kmax``, ``H = (kmin + kmax) / 2``
    dmin, dmax : (n, 3) unit principal directions, tangent, ``dmin x dmax = n``
    area_element : (n,) ``sqrt(det I)``, surface area per unit sphere area
    valid : (n,) bool; False only with ``on_degenerate="nan"``, where every derived quantity
        (all but ``x``) is NaN

    Examples
    --------
    >>> from sns_np.geometry import differential_quantities
    >>> from sns_np.shapes import Ellipsoid
    >>> q = differential_quantities(Ellipsoid(1.0, 2.0, 3.0), np.array([[0.0, 0.0, 1.0]]))
    >>> q.x, q.n                                          # the top point and its normal
    (array([[0., 0., 3.]]), array([[0., 0., 1.]]))
    >>> float(q.K[0]), float(q.kmin[0]), float(q.kmax[0])   # kmin = c/b^2, kmax = c/a^2
    (2.25, 0.75, 3.0)
    >>> bool(np.allclose(q.H, (q.kmin + q.kmax) / 2))
    True
    """

    x: np.ndarray
    n: np.ndarray
    I: np.ndarray
    II: np.ndarray
    H: np.ndarray
    K: np.ndarray
    kmin: np.ndarray
    kmax: np.ndarray
    dmin: np.ndarray
    dmax: np.ndarray
    area_element: np.ndarray
    valid: np.ndarray


_SHAPES = {"x": (3,), "n": (3,), "I": (2, 2), "II": (2, 2), "H": (), "K": (), "kmin": (),
           "kmax": (), "dmin": (3,), "dmax": (3,), "area_element": ()}


def differential_quantities(surface, p, *, on_degenerate: str = "raise",
                            tol: float = DEGENERATE_TOL, chunk: int = CHUNK,
                            sphere_tol: float = SPHERE_TOL) -> DifferentialQuantities:
    """All first- and second-order differential quantities from one jet call per chunk.

    With ``JR = [S_u, S_v]`` and ``S_ab`` from the chart (paper Sec. 3.2, Eqs. 3-11):
    ``n = S_u x S_v / |.|``, ``I = JR^T JR``, ``II_ab = -n . S_ab``, ``K = det II / det I``,
    ``kmin, kmax = eig(I^-1 II)``, ``H = (kmin + kmax) / 2``. The map is called once per chunk
    through :func:`sns_np.protocol.directional_jet` with ``D = [e_u, e_v, p]`` and
    ``second=2`` (7 propagated streams for a map that offers directional jets; the full jet
    is contracted otherwise).

    Parameters
    ----------
    surface : surface map (``jet(p, order)``, optionally with ``directions=``)
    p : (n, 3) float array of unit vectors (within ``sphere_tol``; projected onto the sphere)
    on_degenerate : {"raise", "nan"}
        Where ``sigma_min / sigma_max`` of ``J R`` is below ``tol`` (``det I`` near 0):
        ``"raise"`` raises :class:`~sns_np.errors.DegenerateMapError` naming the first such
        point; ``"nan"`` returns NaN there and ``valid = False``.
    tol : float, degeneracy threshold
    chunk : int, points per jet call (bounds memory)

    Returns
    -------
    DifferentialQuantities

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> q = differential_quantities(Sphere(2.0), np.array([[0.0, 0.0, 1.0]]))
    >>> q.H, q.K, q.n
    (array([0.5]), array([0.25]), array([[0., 0., 1.]]))
    """
    check_choice(on_degenerate, "on_degenerate", {"raise", "nan"})
    chunk, tol = check_options(chunk, tol)
    p = sphere_points(p, sphere_tol)
    N = p.shape[0]
    out = {k: np.empty((N,) + s) for k, s in _SHAPES.items()}
    valid = np.ones(N, dtype=bool)
    mode = "raise" if on_degenerate == "raise" else "flag"
    for sl, (y, JR, _, S2), bad in chart_jet_chunks(surface, p, 2, chunk=chunk, tol=tol,
                                                    on_degenerate=mode):
        with np.errstate(invalid="ignore", divide="ignore"):
            n = normals_from_jets(JR)
            II = second_fundamental_form_from_jets(S2, n)
            kmin, kmax, dmin, dmax = principal_from_jets(JR, II)
            ae = area_element_from_jets(JR)
            K = (II[:, 0, 0] * II[:, 1, 1] - II[:, 0, 1] * II[:, 1, 0]) / ae**2
        vals = {"x": y, "n": n, "I": first_fundamental_form_from_jets(JR), "II": II,
                "H": 0.5 * (kmin + kmax), "K": K, "kmin": kmin, "kmax": kmax, "dmin": dmin,
                "dmax": dmax, "area_element": ae}
        for k, v in vals.items():
            if k != "x":
                v[bad] = np.nan
            out[k][sl] = v
        valid[sl] = ~bad
    return DifferentialQuantities(valid=valid, **out)


def _first_order(surface, p, chunk, sphere_tol, fn, shape):
    p = sphere_points(p, sphere_tol)
    N = p.shape[0]
    out = np.empty((N,) + shape)
    for sl, (_, JR), _ in chart_jet_chunks(surface, p, 1, chunk=int(chunk), on_degenerate="flag"):
        out[sl] = fn(JR)
    return out


def normals(surface, p, *, chunk: int = CHUNK, sphere_tol: float = SPHERE_TOL) -> np.ndarray:
    """Outward unit normals ``n = S_u x S_v / |S_u x S_v|`` (paper Eq. 5), (n, 3).

    Uses a first-order jet along ``e_u, e_v`` only. Degenerate points give NaN (use
    :func:`differential_quantities` for a checked version).

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> normals(Ellipsoid(1.0, 2.0, 3.0), np.array([[0.0, 1.0, 0.0]]))
    array([[0., 1., 0.]])
    """
    return _first_order(surface, p, chunk, sphere_tol, normals_from_jets, (3,))


def first_fundamental_form(surface, p, *, chunk: int = CHUNK,
                           sphere_tol: float = SPHERE_TOL) -> np.ndarray:
    """``I = (J R)^T (J R)`` (paper Eq. 7) in the frame of ``tangent_frame(p)``, (n, 2, 2).

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> first_fundamental_form(Sphere(3.0), np.array([[1.0, 0.0, 0.0]]))[0]
    array([[9., 0.],
           [0., 9.]])
    """
    return _first_order(surface, p, chunk, sphere_tol, first_fundamental_form_from_jets, (2, 2))


def area_element(surface, p, *, chunk: int = CHUNK, sphere_tol: float = SPHERE_TOL):
    """``sqrt(det I)``: surface area per unit sphere area, (n,). ``integral over the sphere of
    area_element = area of the surface``.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> area_element(Sphere(3.0), np.array([[1.0, 0.0, 0.0]]))
    array([9.])
    """
    return _first_order(surface, p, chunk, sphere_tol, area_element_from_jets, ())


def second_fundamental_form(surface, p, **kw) -> np.ndarray:
    """``II_ab = -n . S_ab`` (paper Eq. 9, convex-positive sign), (n, 2, 2).

    Keyword arguments are those of :func:`differential_quantities`.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> second_fundamental_form(Sphere(1.0), np.array([[0.0, 0.0, 1.0]]))[0] + 0.0
    array([[1., 0.],
           [0., 1.]])
    """
    return differential_quantities(surface, p, **kw).II


def mean_curvature(surface, p, **kw) -> np.ndarray:
    """``H = tr(I^-1 II) / 2 = (Eg - 2Ff + Ge) / (2 (EG - F^2))`` (paper Eq. 11), (n,).

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> mean_curvature(Sphere(4.0), np.array([[0.0, 0.0, 1.0]]))
    array([0.25])
    """
    return differential_quantities(surface, p, **kw).H


def gaussian_curvature(surface, p, **kw) -> np.ndarray:
    """``K = det II / det I = (eg - f^2) / (EG - F^2)`` (paper Eq. 10), (n,).

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> gaussian_curvature(Sphere(2.0), np.array([[0.0, 0.0, 1.0]]))
    array([0.25])
    """
    return differential_quantities(surface, p, **kw).K


def principal_curvatures(surface, p, **kw):
    """``(kmin, kmax)``, the eigenvalues of ``I^-1 II`` (roots of ``det(II - k I) = 0``).

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> principal_curvatures(Sphere(2.0), np.array([[0.0, 0.0, 1.0]]))
    (array([0.5]), array([0.5]))
    """
    q = differential_quantities(surface, p, **kw)
    return q.kmin, q.kmax


def principal_directions(surface, p, **kw):
    """``(dmin, dmax)``: unit tangent principal directions in R^3, ``dmin x dmax = n``.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> dmin, dmax = principal_directions(Ellipsoid(1.0, 2.0, 3.0), np.array([[1.0, 0, 0]]))
    >>> np.abs(dmax).round(12)  # the tighter bend at (1, 0, 0) is along y (b < c)
    array([[0., 1., 0.]])
    """
    q = differential_quantities(surface, p, **kw)
    return q.dmin, q.dmax
