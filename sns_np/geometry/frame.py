"""The local orthonormal frame ``R(p) = [e_u, e_v]`` on the unit sphere (paper Sec. 3.2)."""

from __future__ import annotations

import numpy as np

from .._validation import SPHERE_TOL, as_sphere_points

__all__ = ["tangent_frame", "sphere_points"]


def sphere_points(p, tol: float = SPHERE_TOL) -> np.ndarray:
    """Validate (n, 3) points on the unit sphere (``| |p| - 1 | <= tol``) and project them.

    Geometry is evaluated at ``p / |p|``: a point accepted within the tolerance is moved onto
    the sphere (by at most ``tol``) so that the chart and the surface point agree exactly.
    Raises :class:`~sns_np.errors.ShapeError` for points farther off, wrong shapes or
    non-finite values.

    Examples
    --------
    >>> sphere_points(np.array([[0.0, 0.0, 1.0 + 1e-12]]))   # projected back onto the sphere
    array([[0., 0., 1.]])
    >>> sphere_points(np.array([[0.0, 0.0, 2.0]]))
    Traceback (most recent call last):
        ...
    sns_np.errors.ShapeError: p must lie on the unit sphere ...
    """
    p = as_sphere_points(p, "p", tol=tol)
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _frame(p: np.ndarray) -> np.ndarray:
    """Frame of unit points ``p`` (no validation); see :func:`tangent_frame`."""
    # chart with polar axis z where |z| < 0.5, otherwise polar axis x through the cyclic
    # relabelling q = (y, z, x) (a rotation, so e_u x e_v = p is kept); sin(theta) >= 0.5
    polar = np.abs(p[:, 2]) >= 0.5
    q = np.where(polar[:, None], p[:, [1, 2, 0]], p)
    rho = np.hypot(q[:, 0], q[:, 1])
    cphi, sphi = q[:, 0] / rho, q[:, 1] / rho
    zeros = np.zeros_like(rho)
    e_u = np.stack([q[:, 2] * cphi, q[:, 2] * sphi, -rho], axis=1)  # (cos th cos ph, ..)
    e_v = np.stack([-sphi, cphi, zeros], axis=1)
    R = np.stack([e_u, e_v], axis=2)
    R[polar] = R[polar][:, [2, 0, 1], :]  # back from q = (y, z, x) to p = (x, y, z)
    return R


def tangent_frame(p, tol: float = SPHERE_TOL) -> np.ndarray:
    """Orthonormal tangent frame ``R = [e_u, e_v]`` with ``e_u x e_v = p``.

    The paper's rotation matrix (Sec. 3.2, Eq. 6),

        R = [[cos th cos ph, -sin ph], [cos th sin ph, cos ph], [-sin th, 0]],

    i.e. ``e_u = d/dtheta``, ``e_v = d/dphi / sin(theta)`` of spherical polar coordinates.
    Where ``|z| >= 0.5`` the axes are relabelled cyclically, ``(x, y, z) -> (y, z, x)``, so
    that the polar axis is ``x`` and ``sin(theta) >= 0.5`` in both charts: the frame is smooth
    in each chart and never degenerate. Everything reported by :mod:`sns_np.geometry` is
    independent of this choice.

    Parameters
    ----------
    p : (n, 3) float array of unit vectors (within ``tol``; projected onto the sphere)

    Returns
    -------
    R : (n, 3, 2) float array, columns ``e_u``, ``e_v``

    Examples
    --------
    >>> R = tangent_frame(np.array([[1.0, 0.0, 0.0]]))
    >>> R[0] + 0.0
    array([[ 0.,  0.],
           [ 0.,  1.],
           [-1.,  0.]])
    >>> np.cross(R[0, :, 0], R[0, :, 1])
    array([1., 0., 0.])
    """
    return _frame(sphere_points(p, tol))
