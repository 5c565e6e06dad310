"""Differential quantities from jets that are already computed (no call into the map).

These are the building blocks of :func:`sns_np.geometry.differential_quantities`; other
modules (fitting losses, eigenmode optimisation, sampling) use them on arrays they already
hold. Notation (paper Sec. 3.2, DESIGN.md):

* ``JR`` (n, 3, 2): ``[S_u, S_v] = J R``, the map's derivatives along the frame ``e_u, e_v``.
* ``S2`` (n, 3, 2, 2): the second derivatives of the map along the sphere,
  ``S_ab = D2[e_a, e_b] - delta_ab J p``, i.e. the second derivatives at ``0`` of
  ``(u, v) -> S((p + u e_u + v e_v) / |p + u e_u + v e_v|)``; the second term is the sphere's
  own curvature (the chart's second derivatives are ``-delta_ab p``).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "tangent_jacobian", "sphere_second_derivatives", "frame_jets", "normals_from_jets",
    "normals_from_tangents",
    "first_fundamental_form_from_jets", "area_element_from_jets", "inverse_metric",
    "second_fundamental_form_from_jets", "curvatures_from_forms", "principal_from_jets",
    "metric_conditioning",
]

_EYE2 = np.eye(2)


def tangent_jacobian(J: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``J_local = J R`` (paper Eq. 3): columns ``S_u = J e_u``, ``S_v = J e_v``.

    Parameters
    ----------
    J : (n, 3, 3) float array, ambient Jacobian
    R : (n, 3, 2) float array, tangent frame

    Returns
    -------
    JR : (n, 3, 2) float array

    Examples
    --------
    >>> tangent_jacobian(np.eye(3)[None], np.eye(3)[None, :, :2]).shape
    (1, 3, 2)
    """
    return np.einsum("kia,kab->kib", J, R)


def sphere_second_derivatives(D2R: np.ndarray, Jp: np.ndarray) -> np.ndarray:
    """``S_ab = D2[e_a, e_b] - delta_ab J p`` (paper Eq. 8 with the sphere-curvature term).

    Parameters
    ----------
    D2R : (n, 3, 2, 2) float array, ``D2`` contracted with ``e_a, e_b``
    Jp : (n, 3) float array, the radial derivative ``J p``

    Returns
    -------
    S2 : (n, 3, 2, 2) float array

    Examples
    --------
    >>> S2 = sphere_second_derivatives(np.zeros((1, 3, 2, 2)), np.array([[0.0, 0.0, 1.0]]))
    >>> S2[0, 2] + 0.0
    array([[-1.,  0.],
           [ 0., -1.]])
    """
    return D2R - Jp[:, :, None, None] * _EYE2.astype(D2R.dtype, copy=False)  # float32 stays


def frame_jets(J: np.ndarray, D2: np.ndarray, R: np.ndarray, p: np.ndarray):
    """``(JR, S2)`` from full ambient jets ``J`` (n, 3, 3), ``D2`` (n, 3, 3, 3).

    Examples
    --------
    >>> p = np.array([[0.0, 0.0, 1.0]]); R = np.eye(3)[None, :, :2]
    >>> JR, S2 = frame_jets(np.eye(3)[None], np.zeros((1, 3, 3, 3)), R, p)
    >>> JR.shape, S2.shape
    ((1, 3, 2), (1, 3, 2, 2))
    """
    JR = tangent_jacobian(J, R)
    D2R = np.einsum("kiab,kac,kbd->kicd", D2, R, R, optimize=True)
    return JR, sphere_second_derivatives(D2R, np.einsum("kia,ka->ki", J, p))


#: what :func:`normals_from_tangents` returns where ``S_u x S_v = 0``
DEGENERATE_NORMALS = ("nan", "zero")


def normals_from_tangents(Su: np.ndarray, Sv: np.ndarray, *, degenerate: str = "nan"):
    """Unit normals ``n = S_u x S_v / |S_u x S_v|`` (paper Eq. 5) and the norms ``|S_u x S_v|``.

    The one normal computation of the package. Policy where the tangents are degenerate
    (``S_u x S_v = 0``):

    * ``degenerate="nan"`` (geometry): the normal is undefined and comes back NaN, so a
      reported quantity can never look valid there; the geometry functions flag such points
      with :func:`sns_np.geometry.chart.degenerate_mask` (or raise) before using ``n``.
    * ``degenerate="zero"`` (training losses): the norm is clamped to the dtype's smallest
      normal number, so ``n = 0`` there and every value stays finite; the position + normal
      loss and its cotangents (:func:`sns_np.surface.position_normal_loss`) divide by the same
      clamped norm, so a momentarily degenerate network point cannot turn a step into NaN.

    Both agree bitwise wherever ``|S_u x S_v| >= tiny``.

    Parameters
    ----------
    Su, Sv : (n, 3) float arrays (float32 or float64; the result keeps the dtype)
    degenerate : {"nan", "zero"}

    Returns
    -------
    n : (n, 3) float array
    norm : (n,) float array, ``|S_u x S_v|`` (the area element when ``S_u, S_v`` come from the
        orthonormal frame)

    Examples
    --------
    >>> n, norm = normals_from_tangents(np.array([[2.0, 0, 0]]), np.array([[0, 3.0, 0]]))
    >>> n.tolist(), norm.tolist()
    ([[0.0, 0.0, 1.0]], [6.0])
    >>> normals_from_tangents(np.zeros((1, 3)), np.zeros((1, 3)), degenerate="zero")[0]
    array([[0., 0., 0.]])
    """
    if degenerate not in DEGENERATE_NORMALS:
        raise ValueError(f"degenerate must be one of {DEGENERATE_NORMALS}, got {degenerate!r}")
    c = np.cross(Su, Sv)
    norm = np.linalg.norm(c, axis=1)
    if degenerate == "zero":
        return c / np.maximum(norm, np.finfo(c.dtype).tiny)[:, None], norm
    with np.errstate(invalid="ignore", divide="ignore"):
        return c / norm[:, None], norm


def normals_from_jets(JR: np.ndarray, *, degenerate: str = "nan") -> np.ndarray:
    """Unit normal ``n = S_u x S_v / |S_u x S_v|`` (paper Eq. 5) from ``JR = [S_u, S_v]``
    (n, 3, 2), outward for an orientation-preserving map. Degenerate rows give NaN (the
    policy of :func:`normals_from_tangents`).

    Examples
    --------
    >>> normals_from_jets(np.eye(3)[None, :, :2])
    array([[0., 0., 1.]])
    """
    return normals_from_tangents(JR[:, :, 0], JR[:, :, 1], degenerate=degenerate)[0]


def first_fundamental_form_from_jets(JR: np.ndarray) -> np.ndarray:
    """``I = (J R)^T (J R) = [[E, F], [F, G]]`` (paper Eq. 7), (n, 2, 2).

    Examples
    --------
    >>> first_fundamental_form_from_jets(2 * np.eye(3)[None, :, :2])[0]
    array([[4., 0.],
           [0., 4.]])
    """
    Su, Sv = JR[:, :, 0], JR[:, :, 1]
    I = np.empty((JR.shape[0], 2, 2))
    I[:, 0, 0] = np.einsum("ki,ki->k", Su, Su)
    I[:, 1, 1] = np.einsum("ki,ki->k", Sv, Sv)
    I[:, 0, 1] = I[:, 1, 0] = np.einsum("ki,ki->k", Su, Sv)
    return I


def area_element_from_jets(JR: np.ndarray) -> np.ndarray:
    """``sqrt(det I) = |S_u x S_v|``: surface area per unit sphere area, (n,).

    Examples
    --------
    >>> area_element_from_jets(2 * np.eye(3)[None, :, :2])
    array([4.])
    """
    return np.linalg.norm(np.cross(JR[:, :, 0], JR[:, :, 1]), axis=1)


def _det2(A):
    return A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]


def inverse_metric(I: np.ndarray) -> np.ndarray:
    """``I^-1 = [[G, -F], [-F, E]] / (EG - F^2)``, (n, 2, 2), in closed form.

    Examples
    --------
    >>> inverse_metric(np.array([[[4.0, 0.0], [0.0, 2.0]]]))[0] + 0.0
    array([[0.25, 0.  ],
           [0.  , 0.5 ]])
    """
    E, F, G = I[:, 0, 0], I[:, 0, 1], I[:, 1, 1]
    det = E * G - F * F
    out = np.empty_like(I)
    with np.errstate(invalid="ignore", divide="ignore"):
        out[:, 0, 0], out[:, 1, 1] = G / det, E / det
        out[:, 0, 1] = out[:, 1, 0] = -F / det
    return out


def second_fundamental_form_from_jets(S2: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``II_ab = -n . S_ab`` (paper Eq. 9 with DESIGN.md's sign: unit sphere ``II = I``).

    Examples
    --------
    >>> S2 = np.zeros((1, 3, 2, 2)); S2[0, 2] = -np.eye(2)
    >>> second_fundamental_form_from_jets(S2, np.array([[0.0, 0.0, 1.0]]))[0] + 0.0
    array([[1., 0.],
           [0., 1.]])
    """
    return -np.einsum("kiab,ki->kab", S2, n)


def _principal(I, II):
    """kmin, kmax, the kmax eigen-angle psi, and ``U^-1 = [[al, be], [0, ga]]`` (``I = U^T U``).

    ``B = U^-T II U^-1`` is symmetric with the eigenvalues of ``I^-1 II``; written out by
    components because batched 2 x 2 einsums cost more than the arithmetic.
    """
    E, F, G = I[:, 0, 0], 0.5 * (I[:, 0, 1] + I[:, 1, 0]), I[:, 1, 1]
    e, f, g = II[:, 0, 0], 0.5 * (II[:, 0, 1] + II[:, 1, 0]), II[:, 1, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.sqrt(E)
        c = np.sqrt(np.maximum(E * G - F * F, 0.0)) / a
        al, be, ga = 1.0 / a, -F / (a * a * c), 1.0 / c
    m11 = al * al * e
    m12 = al * (e * be + f * ga)
    m22 = e * be * be + 2.0 * f * be * ga + g * ga * ga
    mean = 0.5 * (m11 + m22)
    d = np.hypot(0.5 * (m11 - m22), m12)  # >= 0, no cancellation at umbilics
    psi = 0.5 * np.arctan2(2.0 * m12, m11 - m22)  # eigenvector of kmax: (cos psi, sin psi)
    return mean - d, mean + d, psi, (al, be, ga)


def curvatures_from_forms(I: np.ndarray, II: np.ndarray):
    """Mean, Gauss and principal curvatures from the fundamental forms (paper Eqs. 10-11).

    ``kmin <= kmax`` are the eigenvalues of ``I^-1 II``, computed as those of the symmetric
    ``U^-T II U^-1`` (``I = U^T U``); ``H = (kmin + kmax) / 2 = tr(I^-1 II) / 2`` holds exactly
    (``H`` is computed from ``kmin, kmax``), ``K = det II / det I``.

    Parameters
    ----------
    I, II : (n, 2, 2) float arrays

    Returns
    -------
    H, K, kmin, kmax : (n,) float arrays

    Examples
    --------
    >>> I = np.eye(2)[None]; II = np.diag([1.0, 3.0])[None]
    >>> curvatures_from_forms(I, II)
    (array([2.]), array([3.]), array([1.]), array([3.]))
    """
    kmin, kmax, _, _ = _principal(I, II)
    with np.errstate(invalid="ignore", divide="ignore"):
        K = _det2(II) / _det2(I)
    return 0.5 * (kmin + kmax), K, kmin, kmax


def principal_from_jets(JR: np.ndarray, II: np.ndarray):
    """Principal curvatures and unit principal directions in R^3.

    ``JR U^-1`` is an orthonormal basis ``T`` of the tangent plane (Gram-Schmidt of
    ``S_u, S_v``); eigenvectors ``v`` of ``B = U^-T II U^-1`` give ``d = T v``. The pair is
    right-handed with the normal: ``dmin x dmax = n``. At umbilics (``kmin = kmax``) any
    orthonormal pair is principal; the one returned then depends on the frame.

    Parameters
    ----------
    JR : (n, 3, 2) float array
    II : (n, 2, 2) float array

    Returns
    -------
    kmin, kmax : (n,) float arrays
    dmin, dmax : (n, 3) float arrays

    Examples
    --------
    >>> JR = np.eye(3)[None, :, :2]; II = np.diag([3.0, 1.0])[None]
    >>> kmin, kmax, dmin, dmax = principal_from_jets(JR, II)
    >>> dmax[0], kmax[0]
    (array([1., 0., 0.]), np.float64(3.0))
    """
    kmin, kmax, psi, (al, be, ga) = _principal(first_fundamental_form_from_jets(JR), II)
    Su, Sv = JR[:, :, 0], JR[:, :, 1]
    t1 = al[:, None] * Su
    t2 = be[:, None] * Su + ga[:, None] * Sv
    c, s = np.cos(psi)[:, None], np.sin(psi)[:, None]
    dmax = c * t1 + s * t2
    dmin = s * t1 - c * t2
    return kmin, kmax, dmin, dmax


def metric_conditioning(I: np.ndarray) -> np.ndarray:
    """``sigma_min / sigma_max`` of ``J R`` from ``I``: ``sqrt(det I) / lambda_max(I)``.

    0 for a degenerate (rank-deficient) parametrisation, 1 for a conformal one; geometry
    flags a point as degenerate when this falls below its ``tol``.

    Examples
    --------
    >>> metric_conditioning(np.array([[[4.0, 0.0], [0.0, 1.0]]]))
    array([0.5])
    """
    E, F, G = I[:, 0, 0], I[:, 0, 1], I[:, 1, 1]
    lmax = 0.5 * (E + G) + np.hypot(0.5 * (E - G), F)
    det = np.maximum(E * G - F * F, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.sqrt(det) / lmax
    return np.where(lmax > 0, out, 0.0)
