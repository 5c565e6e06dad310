"""Fitting losses and their cotangents (the inputs of the engine's reverse mode).

A loss over sample points reduces to per-point cotangents of the network value ``y`` and of
its derivatives ``JD`` along the sphere's tangent directions; ``ResidualMLP.value_and_grad``
turns those into parameter gradients.

Position + normal loss (paper, section 3.1):

    loss = 1/N sum |S(p_i) - q_i|^2 + lambda 1/N sum |n(p_i) - n_i|^2
    n = c / |c|,  c = S_u x S_v,  S_u = J e_u, S_v = J e_v

Cotangents, with g = dL/dc:

    dL/dy   = 2 (y - q) / N
    dL/dn   = 2 lambda (n - n_i) / N
    g       = (I - n n^T) dL/dn / |c|         (derivative of c -> c / |c|)
    dL/dS_u = S_v x g,   dL/dS_v = g x S_u     (from d(S_u x S_v) . g)

With ``normal_huber`` (an angle delta, chord d = 2 sin(delta / 2)) each point's squared
normal error s = |n - n_i|^2 enters through the pseudo-Huber function

    rho(s) = 2 d^2 (sqrt(1 + s / d^2) - 1),     rho'(s) = 1 / sqrt(1 + s / d^2),

which is s for s << d^2 and grows like 2 d |n - n_i| beyond: errors larger than delta count
by their size, not its square, so a few points with large errors no longer steer the fit
(the fit is judged by the mean angle). dL/dn is then scaled by rho'(s) per point.

Weights by the fitted surface's own area (a mesh's nearest-point phase, ``area_weight_max``):
training points are drawn by the mesh's area through the embedding, whose map has the area
element ``rho`` (per face: its share of the surface's area over its share of the sphere's),
while the fit is judged over the surface it makes, whose area element is ``|S_u x S_v|``.
Each point's terms are weighted by ``clip(|S_u x S_v| / rho, 1 / m, m)``, held constant in
the gradient (a weight that the fit could lower by shrinking a patch would reward it).

Jacobian loss (an analytic map, whose derivatives along the sphere are exact data):

    loss = mu 1/N sum |JD_i - T_i|^2_F,     dL/dJD = 2 mu (JD - T) / N

Hessian loss (an analytic map's second derivatives along the sphere, ``S_ab = D2[e_a, e_b] -
delta_ab J p`` of :func:`sns_np.geometry.sphere_second_derivatives`; the sphere's own
curvature makes the radial derivative ``J p`` part of them):

    loss = nu 1/N sum |S2_i - T2_i|^2_F,    dL/dD2[e_a, e_b] = G_ab = 2 nu (S2 - T2)_ab / N,
                                            dL/d(J p) = -(G_uu + G_vv)
"""

from __future__ import annotations

import numpy as np

# the one normal function (geometry owns it); re-exported here and from sns_np.surface
from ..geometry.forms import normals_from_tangents, sphere_second_derivatives

__all__ = ["hessian_loss", "jacobian_loss", "normals_from_tangents", "own_area_weights",
           "position_normal_loss"]


def position_normal_loss(y, JD, q, normals, n_total, normal_weight=1e-4, scale=1.0,
                         tangent_weight=1.0, sample_weight=None, pointwise=False,
                         normal_huber=0.0):
    """Position + normal loss on one chunk and its cotangents.

    Parameters
    ----------
    y : (c, 3) float array, network values at the chunk's sphere points
    JD : (c, 3, 2) float array, derivatives along e_u, e_v (``None`` when normal_weight is 0)
    q : (c, 3) float array, target positions
    normals : (c, 3) float array, unit target normals (ignored when normal_weight is 0)
    n_total : int, the number N of points in the whole batch (the mean's denominator)
    normal_weight : float, lambda
    scale : float, the surface is ``scale * y`` (an output transform); positions are compared
        after it, normals are scale-invariant
    tangent_weight : float, weight of the tangential part of the position error
    sample_weight : (c,) float array, optional
        Per-point weights of the sum (importance weights of a non-uniform draw: with weights
        ``density_uniform / density_drawn`` the expected loss is the uniform one).
    pointwise : bool
        Also return each point's unweighted error ``|r|^2 + lambda |n - n_i|^2`` as
        ``parts["pointwise"]`` (what an error-weighted sampler observes).
    normal_huber : float, degrees
        The angle beyond which a point's normal error counts linearly, not quadratically
        (the pseudo-Huber function of the module docstring); 0: squared throughout. The
        summed normal error in ``parts`` and the pointwise errors stay squared.

    Returns
    -------
    loss : float (this chunk's contribution)
    dy : (c, 3) float array
    dJD : (c, 3, 2) float array or None
    parts : dict with the chunk's summed (weighted) squared position and normal errors

    Examples
    --------
    >>> y = np.array([[1.0, 0.0, 0.0]])
    >>> JD = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])      # S_u = e_y, S_v = e_z
    >>> q, nt = np.array([[1.5, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    >>> loss, dy, dJD, parts = position_normal_loss(y, JD, q, nt, 1, normal_weight=1.0)
    >>> loss, dy.tolist()                            # the normal (1, 0, 0) already agrees
    (0.25, [[-1.0, 0.0, 0.0]])
    >>> position_normal_loss(y, JD, q, nt, 1, 1.0, tangent_weight=0.1)[0]   # all normal
    0.25
    >>> nt = np.array([[0.0, 1.0, 0.0]])             # 90 degrees off: squared error 2
    >>> [round(position_normal_loss(y, JD, q, nt, 1, 1.0, normal_huber=h)[0] - 0.25, 4)
    ...  for h in (0.0, 2.0, 180.0)]
    [2.0, 0.0963, 1.798]
    """
    r = scale * y - q
    if tangent_weight != 1.0:
        # |r|^2 -> (r . n_t)^2 + t |r - (r . n_t) n_t|^2: the tangential part of the error
        # moves points along the surface, not off it
        rn = np.einsum("ij,ij->i", r, normals)[:, None] * normals
        rw = rn + tangent_weight * (r - rn)
    else:
        rw = r
    per_pos = np.einsum("ij,ij->i", r, r)
    per_loss = per_pos if rw is r else np.einsum("ij,ij->i", r, rw)
    if sample_weight is not None:
        sample_weight = np.asarray(sample_weight, dtype=r.dtype)
        rw = sample_weight[:, None] * rw

    def total(v):                       # the chunk's (weighted) sum of per-point values
        return float(v.sum() if sample_weight is None else sample_weight @ v)

    loss = total(per_loss) / n_total
    dy = (2.0 * scale / n_total) * rw
    parts = {"position": total(per_pos), "normal": 0.0}
    if not normal_weight:
        if pointwise:
            parts["pointwise"] = per_loss
        return loss, dy, None, parts
    Su, Sv = JD[:, :, 0], JD[:, :, 1]
    n, norm = normals_from_tangents(Su, Sv, degenerate="zero")
    dn = n - normals
    per_nrm = np.einsum("ij,ij->i", dn, dn)
    sq_nrm = total(per_nrm)
    parts["normal"] = sq_nrm
    if pointwise:
        parts["pointwise"] = per_loss + normal_weight * per_nrm
    if normal_huber:
        d2 = 4.0 * float(np.sin(np.radians(normal_huber) / 2.0)) ** 2   # keeps the dtype
        root = np.sqrt(1.0 + per_nrm / d2)
        loss += normal_weight * total(2.0 * d2 * (root - 1.0)) / n_total
        dn = dn / root[:, None]
    else:
        loss += normal_weight * sq_nrm / n_total
    if sample_weight is not None:
        dn = sample_weight[:, None] * dn
    gn = (2.0 * normal_weight / n_total) * dn
    g = (gn - np.einsum("ij,ij->i", n, gn)[:, None] * n) / np.maximum(
        norm, np.finfo(norm.dtype).tiny)[:, None]
    dJD = np.empty_like(JD)
    dJD[:, :, 0] = np.cross(Sv, g)
    dJD[:, :, 1] = np.cross(g, Su)
    return loss, dy, dJD, parts


def own_area_weights(JD, density, most):
    """Per-point weights that carry the embedding's measure over to the fitted surface's own:
    the map's area element over the embedding's, clipped to ``[1 / most, most]``.

    Parameters
    ----------
    JD : (c, 3, 2) float array, the map's derivatives along an orthonormal tangent frame
        of the sphere (in the units of the targets, as in :func:`position_normal_loss`)
    density : (c,) float array, the embedding's area element at each point (> 0)
    most : float >= 1, the largest factor either way

    Returns
    -------
    w : (c,) array of JD's dtype, in ``[1 / most, most]``

    Examples
    --------
    >>> JD = np.array([[[2.0, 0.0], [0.0, 3.0], [0.0, 0.0]]] * 3)  # area element 6
    >>> own_area_weights(JD, np.array([6.0, 1.0, 60.0]), 4.0).tolist()
    [1.0, 4.0, 0.25]
    """
    most = float(most)
    if not most >= 1.0:
        raise ValueError(f"most must be a factor >= 1, got {most!r}")
    area = np.linalg.norm(np.cross(JD[:, :, 0], JD[:, :, 1]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):    # a degenerate face: a bound or 1
        ratio = area / np.asarray(density, dtype=area.dtype)
    return np.clip(np.nan_to_num(ratio, nan=1.0), 1.0 / most, most).astype(JD.dtype,
                                                                          copy=False)


def jacobian_loss(JD, JT, n_total, weight=1.0, sample_weight=None):
    """Squared error of the derivatives along the sphere on one chunk, and its cotangent.

    Parameters
    ----------
    JD : (c, 3, 2) float array, the network's derivatives along e_u, e_v
    JT : (c, 3, 2) float array, the target's derivatives along the same directions
    n_total : int, the number N of points in the whole batch (the mean's denominator)
    weight : float, mu
    sample_weight : (c,) float array, optional, per-point weights of the sum (as in
        :func:`position_normal_loss`)

    Returns
    -------
    loss : float (this chunk's contribution), dJD : (c, 3, 2) float array, sq : float (the
    chunk's summed squared error, weighted by ``sample_weight`` only)

    Examples
    --------
    >>> JD = np.zeros((2, 3, 2))
    >>> JT = np.zeros((2, 3, 2)); JT[0, 0, 0] = 1.0
    >>> loss, dJD, sq = jacobian_loss(JD, JT, 2, weight=0.5)
    >>> loss, float(dJD[0, 0, 0]), sq                  # 0.5 * 1 / 2, 2 * 0.5 * (0 - 1) / 2
    (0.25, -0.5, 1.0)
    """
    E = JD - JT
    if sample_weight is None:
        sq = float(np.einsum("kia,kia->", E, E))
        return weight * sq / n_total, (2.0 * weight / n_total) * E, sq
    sw = np.asarray(sample_weight, dtype=E.dtype)
    sq = float(sw @ np.einsum("kia,kia->k", E, E))
    return weight * sq / n_total, (2.0 * weight / n_total) * (sw[:, None, None] * E), sq


def hessian_loss(D2D, Jp, T2, n_total, weight=1.0, sample_weight=None):
    """Squared error of the second derivatives along the sphere on one chunk, and cotangents.

    Parameters
    ----------
    D2D : (c, 3, 2, 2) float array, the network's ambient second derivatives ``D2[e_a, e_b]``
    Jp : (c, 3) float array, its radial derivative ``J p``
    T2 : (c, 3, 2, 2) float array, the target's ``S_ab = D2[e_a, e_b] - delta_ab J p``
    n_total : int, the number N of points in the whole batch (the mean's denominator)
    weight : float, nu
    sample_weight : (c,) float array, optional, per-point weights of the sum (as in
        :func:`position_normal_loss`)

    Returns
    -------
    loss : float (this chunk's contribution), dD2D : (c, 3, 2, 2) float array, dJp : (c, 3)
    float array, sq : float (the chunk's summed squared error, weighted by ``sample_weight``
    only)

    Examples
    --------
    >>> D2D, T2 = np.zeros((1, 3, 2, 2)), np.zeros((1, 3, 2, 2))
    >>> Jp = np.array([[0.0, 0.0, 1.0]])       # S_uu = S_vv = -e_z, as on the unit sphere
    >>> loss, dD2D, dJp, sq = hessian_loss(D2D, Jp, T2, 1, weight=0.5)
    >>> loss, sq, (dJp + 0.0).tolist()          # 0.5 * 2, and -(G_uu + G_vv) = -(-1 - 1)
    (1.0, 2.0, [[0.0, 0.0, 2.0]])
    """
    E = sphere_second_derivatives(D2D, Jp) - T2
    if sample_weight is None:
        sq = float(np.einsum("kiab,kiab->", E, E))
        G = (2.0 * weight / n_total) * E
    else:
        sw = np.asarray(sample_weight, dtype=E.dtype)
        sq = float(sw @ np.einsum("kiab,kiab->k", E, E))
        G = (2.0 * weight / n_total) * (sw[:, None, None, None] * E)
    return weight * sq / n_total, G, -(G[:, :, 0, 0] + G[:, :, 1, 1]), sq
