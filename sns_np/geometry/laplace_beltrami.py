"""The Laplace-Beltrami operator ``Delta_S = div_S grad_S`` on any surface map (paper Sec. 4.1).

Two independent evaluation paths (they agree to round-off on smooth inputs):

* ``method="mean_curvature"`` (paper Eq. 16):
  ``Delta_S f = Delta f~ - 2 H grad f~ . n - n^T Hess(f~) n`` from an ambient extension ``f~``.
* ``method="divgrad"`` (paper Eq. 13): the surface divergence of the surface-gradient vector
  field, differentiated in the chart ``q(u, v) = (p + u e_u + v e_v) / |.|`` of the frame.

and two domains for the field (see :mod:`sns_np.geometry.calculus`): ``"sphere"`` (``g`` on
the parameter sphere, ``h(S(p)) = g(p)``, how neural scalar fields are used) and ``"ambient"``
(``f~`` defined around the surface in R^3, evaluated at ``S(p)``).
"""

from __future__ import annotations

import numpy as np

from .._validation import SPHERE_TOL, check_choice
from ..protocol import chunk_slices, field_jet, surface_jet
from .calculus import (
    DOMAINS,
    ambient_field_chart_jets,
    sphere_field_chart_jets,
    surface_divergence_from_jets,
)
from .chart import (
    CHUNK,
    DEGENERATE_TOL,
    check_options,
    checked_chart_jets,
    degenerate_mask,
    raise_degenerate,
)
from .forms import (
    first_fundamental_form_from_jets,
    frame_jets,
    inverse_metric,
    normals_from_jets,
    principal_from_jets,
    second_fundamental_form_from_jets,
)
from .frame import _frame, sphere_points

__all__ = ["laplace_beltrami", "laplace_beltrami_mean_curvature_from_jets",
           "laplace_beltrami_divgrad_from_jets", "sphere_field_extension"]

METHODS = {"mean_curvature", "divgrad"}


def laplace_beltrami_mean_curvature_from_jets(grad_f, hess_f, H, n):
    """``Delta_S f = tr Hess f~ - 2 H grad f~ . n - n^T Hess f~ n`` (paper Eq. 16).

    Parameters
    ----------
    grad_f : (n, 3) float array, ambient gradient of the extension at the surface point
    hess_f : (n, 3, 3) float array, its Hessian
    H : (n,) float array, mean curvature (convex positive)
    n : (n, 3) float array, outward unit normal

    Examples
    --------
    >>> # f = x_3 on the unit sphere at its north pole: Delta_S z = -2 H n_3 = -2
    >>> laplace_beltrami_mean_curvature_from_jets(np.array([[0.0, 0, 1]]), np.zeros((1, 3, 3)),
    ...                                           np.array([1.0]), np.array([[0.0, 0, 1]]))
    array([-2.])
    """
    return (np.trace(hess_f, axis1=1, axis2=2) - 2.0 * H * np.einsum("ki,ki->k", grad_f, n)
            - np.einsum("ki,kij,kj->k", n, hess_f, n))


def laplace_beltrami_divgrad_from_jets(f_a, f_ab, JR, S2):
    """``div_S grad_S h`` from chart derivatives of the field and of the map.

    With ``X_a = JR[:, :, a]``, ``X_ab = S2[:, :, a, b]``, ``w = I^-1 f_a`` (so
    ``V = grad_S h = X_c w_c``)::

        d_a I_cd = X_ac . X_d + X_c . X_ad,        d_a w = I^-1 (f_.a - (d_a I) w),
        d_a V = X_ac w_c + X_c (d_a w)_c,          Delta_S h = X^a . d_a V.

    This is the coordinate formula ``I^ab (h_ab - Gamma^c_ab h_c)`` written as the divergence
    of the gradient field (paper Eq. 13); it needs no normal, no mean curvature and no 3 x 3
    inverse.

    Parameters
    ----------
    f_a : (n, 2), f_ab : (n, 2, 2) chart derivatives of the field
    JR : (n, 3, 2), S2 : (n, 3, 2, 2) chart derivatives of the map

    Examples
    --------
    >>> JR = np.eye(3)[None, :, :2]; S2 = np.zeros((1, 3, 2, 2))  # a flat chart
    >>> laplace_beltrami_divgrad_from_jets(np.zeros((1, 2)), np.diag([1.0, 2.0])[None], JR, S2)
    array([3.])
    """
    Iinv = inverse_metric(first_fundamental_form_from_jets(JR))
    w = np.einsum("kab,kb->ka", Iinv, f_a)
    T = np.einsum("kiac,kid->kacd", S2, JR)  # T[a, c, d] = X_ac . X_d
    dI = T + np.swapaxes(T, 2, 3)
    rhs = np.swapaxes(f_ab, 1, 2) - np.einsum("kacd,kd->kac", dI, w)  # [a, c]
    dw = np.einsum("kcd,kad->kac", Iinv, rhs)  # dw[a, c] = (d_a w)_c
    dV = np.einsum("kiac,kc->kia", S2, w) + np.einsum("kic,kac->kia", JR, dw)
    return surface_divergence_from_jets(dV, JR, Iinv)


def sphere_field_extension(grad_g, hess_g, J, D2):
    """Ambient jets of ``h~ = g o S^-1`` (``S`` a local diffeomorphism of R^3; paper Eq. 24):

        grad h~ = J^-T grad g,      Hess h~ = J^-T (Hess g - sum_i (grad h~)_i D2_i) J^-1,

    from ``grad (g) = J^T grad h~`` and ``Hess g = J^T Hess h~ J + sum_i (grad h~)_i D2_i``.
    The 3 x 3 ``J`` must be invertible (checked by :func:`laplace_beltrami`).

    Returns
    -------
    grad_h : (n, 3), hess_h : (n, 3, 3)

    Examples
    --------
    >>> J = 2 * np.eye(3)[None]  # S(x) = 2 x, g = z: h~ = z / 2
    >>> sphere_field_extension(np.array([[0.0, 0, 1]]), np.zeros((1, 3, 3)), J,
    ...                        np.zeros((1, 3, 3, 3)))[0]
    array([[0. , 0. , 0.5]])
    """
    Jinv = np.linalg.inv(J)
    grad_h = np.einsum("kai,ka->ki", Jinv, grad_g)
    A = hess_g - np.einsum("ki,kiab->kab", grad_h, D2)
    return grad_h, np.einsum("kai,kab,kbj->kij", Jinv, A, Jinv, optimize=True)


def _mean_curvature_chunk(surface, ps, field, domain, tol, offset):
    if domain == "ambient":
        y, JR, _, S2 = checked_chart_jets(surface, ps, None, 2, tol, offset)
        _, grad_f, hess_f = field_jet(field, y, 2)
    else:
        # the extension g o S^-1 needs the full 3 x 3 J and all of D2
        _, J, D2 = surface_jet(surface, ps, 2)
        JR, S2 = frame_jets(J, D2, _frame(ps), ps)
        bad = degenerate_mask(JR, tol)
        if bad.any():
            raise_degenerate(bad, ps, offset)
        sv = np.linalg.svd(J, compute_uv=False)
        bad = ~(sv[:, 2] > tol * sv[:, 0])
        if bad.any():
            raise_degenerate(bad, ps, offset, detail=(
                "its 3 x 3 Jacobian J is singular, so g o S^-1 has no ambient extension; "
                "use method='divgrad', which needs only the derivatives along the sphere"))
        _, grad_g, hess_g = field_jet(field, ps, 2)
        grad_f, hess_f = sphere_field_extension(grad_g, hess_g, J, D2)
    n = normals_from_jets(JR)
    kmin, kmax, _, _ = principal_from_jets(JR, second_fundamental_form_from_jets(S2, n))
    return laplace_beltrami_mean_curvature_from_jets(grad_f, hess_f, 0.5 * (kmin + kmax), n)


def _divgrad_chunk(surface, ps, field, domain, tol, offset):
    y, JR, _, S2 = checked_chart_jets(surface, ps, None, 2, tol, offset)
    if domain == "ambient":
        _, grad_f, hess_f = field_jet(field, y, 2)
        f_a, f_ab = ambient_field_chart_jets(grad_f, hess_f, JR, S2)
    else:
        _, grad_g, hess_g = field_jet(field, ps, 2)
        f_a, f_ab = sphere_field_chart_jets(grad_g, hess_g, _frame(ps), ps)
    return laplace_beltrami_divgrad_from_jets(f_a, f_ab, JR, S2)


def laplace_beltrami(surface, p, field, method: str = "divgrad", domain: str = "sphere", *,
                     chunk: int = CHUNK, tol: float = DEGENERATE_TOL,
                     sphere_tol: float = SPHERE_TOL) -> np.ndarray:
    """``Delta_S`` of a scalar field on the surface ``S(sphere)`` at the points ``S(p)``.

    ``Delta_S = div_S grad_S`` is negative semi-definite: ``Delta_S x = -2 H n``, and on the
    unit sphere ``Delta_S Y_lm = -l(l+1) Y_lm``.

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array of unit vectors (within ``sphere_tol``; projected onto the sphere)
    field : field (``jet(x, 2)`` -> value (n,), gradient (n, 3), Hessian (n, 3, 3))
    method : {"divgrad", "mean_curvature"}
        ``"divgrad"`` (default; paper Eq. 13): divergence of the gradient in the sphere chart.
        It uses only derivatives along the sphere (7 propagated streams for a map with
        directional jets) and works for every regular parametrisation, even one whose 3 x 3
        Jacobian is singular. ``"mean_curvature"`` (paper Eq. 16):
        ``Delta f~ - 2 H grad f~ . n - n^T Hess(f~) n``; with ``domain="sphere"`` it extends
        ``g`` by ``g o S^-1`` and needs the full jet and an invertible 3 x 3 ``J``.
    domain : {"sphere", "ambient"}
        ``"sphere"`` (default, DESIGN.md): ``field`` is ``g`` on the parameter sphere,
        evaluated at ``p``, and the surface field is ``h(S(p)) = g(p)``. ``"ambient"``:
        ``field`` is defined around the surface in R^3 and evaluated at ``S(p)``.
    chunk : int, points per jet call
    tol : float
        Degeneracy threshold on ``sigma_min / sigma_max`` of ``J R`` (and of ``J`` for
        ``mean_curvature`` on the sphere domain); below it
        :class:`~sns_np.errors.DegenerateMapError` is raised naming the point.

    Returns
    -------
    (n,) float array

    Examples
    --------
    >>> from sns_np.shapes import Sphere, SphericalHarmonic
    >>> p = np.array([[0.6, 0.0, 0.8]])
    >>> Y = SphericalHarmonic(2, 1)
    >>> bool(np.allclose(laplace_beltrami(Sphere(), p, Y), -6 * Y.jet(p, 0)))
    True
    """
    check_choice(method, "method", METHODS)
    check_choice(domain, "domain", DOMAINS)
    chunk, tol = check_options(chunk, tol)
    p = sphere_points(p, sphere_tol)
    kernel = _divgrad_chunk if method == "divgrad" else _mean_curvature_chunk
    out = np.empty(p.shape[0])
    for sl in chunk_slices(p.shape[0], chunk):
        out[sl] = kernel(surface, p[sl], field, domain, tol, sl.start)
    return out
