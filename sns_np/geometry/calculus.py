"""Surface gradient and surface divergence (paper Sec. 4.1, Eqs. 14-15) on any surface map.

Two domains for the fields, as in :func:`sns_np.geometry.laplace_beltrami`:

* ``domain="ambient"``: the field is defined around the surface in R^3 and evaluated at
  ``S(p)``; the paper's extrinsic formulas apply directly
  (``grad_S f = grad f - (grad f . n) n``, ``div_S F = div F - n^T J(F) n``).
* ``domain="sphere"``: the field lives on the parameter sphere, the surface field is
  ``h(S(p)) = g(p)``; derivatives go through the chart ``q(u, v)`` of the frame, where
  ``grad_S h = X_a I^ab h_b`` (``X_a = J e_a``) and ``div_S V = X^a . d_a V`` with the dual
  basis ``X^a = I^ab X_b``.
"""

from __future__ import annotations

import numpy as np

from .._validation import SPHERE_TOL, check_choice
from ..protocol import field_jet, surface_jet
from .chart import CHUNK, DEGENERATE_TOL, chart_jet_chunks, check_options
from .forms import first_fundamental_form_from_jets, inverse_metric, normals_from_jets
from .frame import _frame, sphere_points

__all__ = [
    "surface_gradient", "surface_divergence", "surface_gradient_from_jets",
    "surface_divergence_from_jets", "surface_gradient_ambient", "surface_divergence_ambient",
    "sphere_field_chart_jets", "ambient_field_chart_jets",
]

DOMAINS = {"sphere", "ambient"}


def surface_gradient_ambient(grad_f: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``grad_S f = grad f - (grad f . n) n`` (paper Eq. 14), (n, 3).

    Examples
    --------
    >>> surface_gradient_ambient(np.array([[1.0, 2.0, 3.0]]), np.array([[0.0, 0.0, 1.0]]))
    array([[1., 2., 0.]])
    """
    return grad_f - np.einsum("ki,ki->k", grad_f, n)[:, None] * n


def surface_divergence_ambient(JF: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``div_S F = div F - n^T J(F) n`` (paper Eq. 15) for an ambient Jacobian ``JF`` (n, 3, 3).

    Examples
    --------
    >>> surface_divergence_ambient(np.eye(3)[None], np.array([[0.0, 0.0, 1.0]]))
    array([2.])
    """
    return np.trace(JF, axis1=1, axis2=2) - np.einsum("ki,kij,kj->k", n, JF, n)


def surface_gradient_from_jets(f_a: np.ndarray, JR: np.ndarray, Iinv: np.ndarray):
    """``grad_S h = X_a I^ab h_b`` from chart derivatives ``f_a = h_a`` (n, 2), (n, 3).

    Examples
    --------
    >>> JR = 2 * np.eye(3)[None, :, :2]; Iinv = np.eye(2)[None] / 4
    >>> surface_gradient_from_jets(np.array([[2.0, 0.0]]), JR, Iinv)
    array([[1., 0., 0.]])
    """
    return np.einsum("kia,kab,kb->ki", JR, Iinv, f_a)


def surface_divergence_from_jets(dV: np.ndarray, JR: np.ndarray, Iinv: np.ndarray):
    """``div_S V = sum_a X^a . d_a V`` with ``X^a = I^ab X_b`` (the trace of the tangential
    derivative), from the chart derivatives ``dV[:, :, a] = d_a V`` (n, 3, 2).

    Examples
    --------
    >>> JR = np.eye(3)[None, :, :2]  # V = identity on the plane: div = 2
    >>> surface_divergence_from_jets(JR.copy(), JR, np.eye(2)[None])
    array([2.])
    """
    return np.einsum("kab,kib,kia->k", Iinv, JR, dV)


def sphere_field_chart_jets(grad_g, hess_g, R, p):
    """Chart derivatives of ``g(q(u, v))``: ``f_a = grad g . e_a``,
    ``f_ab = Hess g[e_a, e_b] - delta_ab grad g . p`` (the chart's ``q_ab = -delta_ab p``).

    Returns ``f_a`` (n, 2) and ``f_ab`` (n, 2, 2).

    Examples
    --------
    >>> R = np.eye(3)[None, :, :2]; p = np.array([[0.0, 0.0, 1.0]])
    >>> f_a, f_ab = sphere_field_chart_jets(np.array([[0.0, 0, 1]]), np.zeros((1, 3, 3)), R, p)
    >>> f_ab[0] + 0.0  # g = z on the sphere: z = sqrt(1 - u^2 - v^2) ~ 1 - (u^2 + v^2)/2
    array([[-1.,  0.],
           [ 0., -1.]])
    """
    f_a = np.einsum("ka,kab->kb", grad_g, R)
    f_ab = (np.einsum("kac,kab,kbd->kcd", R, hess_g, R, optimize=True)
            - np.einsum("ka,ka->k", grad_g, p)[:, None, None] * np.eye(2))
    return f_a, f_ab


def ambient_field_chart_jets(grad_f, hess_f, JR, S2):
    """Chart derivatives of ``f(X(u, v))``: ``f_a = grad f . X_a``,
    ``f_ab = X_a^T Hess f X_b + grad f . S_ab``. Returns (n, 2) and (n, 2, 2).

    Examples
    --------
    >>> JR = np.eye(3)[None, :, :2]; S2 = np.zeros((1, 3, 2, 2))
    >>> ambient_field_chart_jets(np.ones((1, 3)), np.zeros((1, 3, 3)), JR, S2)[0]
    array([[1., 1.]])
    """
    f_a = np.einsum("ki,kia->ka", grad_f, JR)
    f_ab = (np.einsum("kia,kij,kjb->kab", JR, hess_f, JR, optimize=True)
            + np.einsum("ki,kiab->kab", grad_f, S2))
    return f_a, f_ab


def surface_gradient(surface, p, field, domain: str = "sphere", *, chunk: int = CHUNK,
                     tol: float = DEGENERATE_TOL, sphere_tol: float = SPHERE_TOL):
    """Surface gradient of a scalar field on the surface ``S(sphere)``, as vectors in R^3.

    ``domain="ambient"``: ``grad_S f = grad f - (grad f . n) n`` at ``S(p)`` (paper Eq. 14).
    ``domain="sphere"``: ``h(S(p)) = g(p)``, ``grad_S h = X_a I^ab (grad g . e_a)``.

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array of unit vectors
    field : field (``jet(x, order)`` -> value, gradient, Hessian)
    domain : {"sphere", "ambient"}

    Returns
    -------
    (n, 3) float array, tangent to the surface

    Examples
    --------
    >>> from sns_np.shapes import Sphere, coordinate_field
    >>> surface_gradient(Sphere(2.0), np.array([[1.0, 0, 0]]), coordinate_field(2), "ambient")
    array([[0., 0., 1.]])
    """
    check_choice(domain, "domain", DOMAINS)
    chunk, tol = check_options(chunk, tol)
    p = sphere_points(p, sphere_tol)
    out = np.empty((p.shape[0], 3))
    for sl, (y, JR), _ in chart_jet_chunks(surface, p, 1, chunk=chunk, tol=tol):
        ps = p[sl]
        if domain == "ambient":
            out[sl] = surface_gradient_ambient(field_jet(field, y, 1)[1], normals_from_jets(JR))
        else:
            f_a = np.einsum("ka,kab->kb", field_jet(field, ps, 1)[1], _frame(ps))
            Iinv = inverse_metric(first_fundamental_form_from_jets(JR))
            out[sl] = surface_gradient_from_jets(f_a, JR, Iinv)
    return out


def surface_divergence(surface, p, vector_field, domain: str = "sphere", *,
                       chunk: int = CHUNK, tol: float = DEGENERATE_TOL,
                       sphere_tol: float = SPHERE_TOL):
    """Surface divergence of a vector field on the surface (paper Eq. 15).

    The vector field follows the surface-map protocol (``jet(x, 1)`` -> value (n, 3),
    Jacobian (n, 3, 3)); a normal part contributes too (``div_S (phi n) = 2 H phi`` with the
    convex-positive ``H``).
    ``domain="ambient"``: ``F`` around the surface, ``div_S F = div F - n^T J(F) n`` at ``S(p)``.
    ``domain="sphere"``: ``V(S(p)) = W(p)``, ``d_a V = J(W) e_a``, ``div_S V = X^a . d_a V``.

    Returns
    -------
    (n,) float array

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> surface_divergence(Sphere(2.0), np.array([[1.0, 0, 0]]), Sphere(1.0), "ambient")
    array([2.])
    """
    check_choice(domain, "domain", DOMAINS)
    chunk, tol = check_options(chunk, tol)
    p = sphere_points(p, sphere_tol)
    out = np.empty(p.shape[0])
    for sl, (y, JR), _ in chart_jet_chunks(surface, p, 1, chunk=chunk, tol=tol):
        ps = p[sl]
        if domain == "ambient":
            JF = surface_jet(vector_field, y, 1)[1]
            out[sl] = surface_divergence_ambient(JF, normals_from_jets(JR))
        else:
            dV = np.einsum("kia,kab->kib", surface_jet(vector_field, ps, 1)[1], _frame(ps))
            Iinv = inverse_metric(first_fundamental_form_from_jets(JR))
            out[sl] = surface_divergence_from_jets(dV, JR, Iinv)
    return out
