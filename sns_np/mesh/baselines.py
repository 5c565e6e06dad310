"""Mesh curvature baselines, for comparison with curvatures computed on a neural surface.

Sign convention (DESIGN.md): with outward normals, convex surfaces have positive curvature; the
unit sphere has ``H = K = 1`` and principal curvatures ``(1, 1)``; ``H = (kmin + kmax) / 2``
and ``K = kmin kmax`` whenever both come from one fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._arrays import as_mesh, unique_edges
from .operators import cotan_laplacian, face_angles, mass_matrix, vertex_normals

__all__ = ["Curvatures", "baseline_curvatures", "curvature_jitter", "discrete_curvatures"]


@dataclass(frozen=True)
class Curvatures:
    """Per-vertex curvatures (arrays of length n; directions (n, 3), or None when not given).

    Examples
    --------
    >>> from sns_np.mesh import discrete_curvatures, icosphere
    >>> c = discrete_curvatures(*icosphere(3))
    >>> round(float(c.H.mean()), 3), round(float(c.K.mean()), 3), c.kmin   # unit sphere: 1, 1
    (1.0, 1.005, None)
    """

    H: np.ndarray
    K: np.ndarray
    kmin: np.ndarray | None = None
    kmax: np.ndarray | None = None
    dmin: np.ndarray | None = None
    dmax: np.ndarray | None = None


def discrete_curvatures(V, F) -> Curvatures:
    """Cotangent mean curvature and angle-defect Gaussian curvature (no libigl needed).

    ``H_i = -(L V)_i . n_i / (2 M_ii)`` from ``Delta x = -2 H n`` (mixed-Voronoi mass ``M``,
    angle-weighted normal ``n``) and ``K_i = (2 pi - sum of corner angles at i) / M_ii``
    (Meyer et al. 2003). Principal curvatures are not estimated (``kmin = kmax = None``).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, outward oriented

    Returns
    -------
    Curvatures

    References
    ----------
    M. Meyer, M. Desbrun, P. Schröder and A. H. Barr, "Discrete differential-geometry operators
    for triangulated 2-manifolds", Visualization and Mathematics III, 2003.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(4)
    >>> c = discrete_curvatures(V, F)
    >>> round(float(c.H.mean()), 2), round(float(c.K.mean()), 2)
    (1.0, 1.0)
    """
    V, F = as_mesh(V, F)
    m = mass_matrix(V, F, "voronoi").diagonal()
    n = vertex_normals(V, F)
    H = -np.einsum("ij,ij->i", cotan_laplacian(V, F) @ V, n) / (2.0 * m)
    angle_sum = np.bincount(F.ravel(), weights=face_angles(V, F).ravel(), minlength=V.shape[0])
    return Curvatures(H=H, K=(2.0 * np.pi - angle_sum) / m)


def curvature_jitter(V, F) -> float:
    """How much a mesh's mean curvature changes from one vertex to the next, relative to its
    size: the area-weighted mean of ``|H_i - mean_j H_j|`` over that of ``|H_i|``, with
    ``H_i`` the cotangent mean curvature of :func:`discrete_curvatures` at vertex ``i``, its
    mixed-Voronoi area the weight and ``j`` its neighbours.

    Where a mesh samples a surface that is smooth at its vertex spacing the curvature changes
    little between neighbours (the demo's ellipsoid 0.004, SPIKE meshed at icosphere level 5
    0.07); scans and sculptures carry detail as fine as their vertices (spot 0.23, the
    armadillo 0.70), and a sharp edge's curvature lives on its vertices alone (a meshed cube
    1.3). Invariant to scale and to rigid motions. docs/fitting.md, "A fine sample of a
    smooth surface".

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> round(curvature_jitter(V, F), 4)                       # on the sphere: H constant
    0.0
    >>> round(curvature_jitter(V * [1.0, 1.3, 0.7], F), 3)     # an ellipsoid
    0.013
    >>> bumps = 1 + 0.01 * np.random.default_rng(0).standard_normal(len(V))
    >>> round(curvature_jitter(V * bumps[:, None], F), 2)      # 1% noise at the vertices
    0.81
    """
    V, F = as_mesh(V, F)
    H = discrete_curvatures(V, F).H
    area = mass_matrix(V, F, "voronoi").diagonal()
    E = unique_edges(F, len(V))[0]
    i, j = np.concatenate([E[:, 0], E[:, 1]]), np.concatenate([E[:, 1], E[:, 0]])
    around = np.bincount(i, H[j], len(V)) / np.bincount(i, minlength=len(V))
    size = float(np.sum(area * np.abs(H)))
    if not size > 0:
        raise ValueError("the mesh's mean curvature is zero at every vertex (a flat or "
                         "degenerate mesh); curvature_jitter needs a closed curved surface")
    return float(np.sum(area * np.abs(H - around)) / size)


def baseline_curvatures(V, F, *, radius: int = 5) -> Curvatures:
    """Principal curvatures by local quadric fitting (libigl ``principal_curvature``).

    Needs the optional dependency libigl (``pip install 'sns-np[baselines]'``).

    Parameters
    ----------
    V : (n, 3) float array
    F : (m, 3) int array, outward oriented (libigl's signs follow the orientation, which for an
        outward mesh is our convention: convex positive)
    radius : int
        Neighbourhood size of the fit in average edge lengths (libigl's parameter).

    Returns
    -------
    Curvatures
        ``kmin <= kmax``, ``H = (kmin + kmax) / 2``, ``K = kmin kmax``, unit principal
        directions ``dmin``, ``dmax``.

    References
    ----------
    D. Panozzo, E. Puppo and L. Rocca, "Efficient multi-scale curvature and crease
    estimation", Computer Graphics, Computer Vision and Mathematics (GraVisMa), 2010.

    Examples
    --------
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(4)
    >>> c = baseline_curvatures(2.0 * V, F)               # radius 2: curvatures 1/2
    >>> round(float(c.kmin.mean()), 2), round(float(c.kmax.mean()), 2)
    (0.51, 0.51)
    """
    try:
        import igl
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("baseline_curvatures needs libigl: pip install 'sns-np[baselines]'") \
            from exc
    V, F = as_mesh(V, F)
    dmax, dmin, kmax, kmin, _ = igl.principal_curvature(V, F, radius=radius)
    kmax, kmin = np.asarray(kmax, dtype=np.float64), np.asarray(kmin, dtype=np.float64)
    swap = kmin > kmax                                   # keep kmin <= kmax row by row
    kmin, kmax = np.where(swap, kmax, kmin), np.where(swap, kmin, kmax)
    dmin, dmax = (np.where(swap[:, None], dmax, dmin), np.where(swap[:, None], dmin, dmax))
    return Curvatures(H=0.5 * (kmin + kmax), K=kmin * kmax, kmin=kmin, kmax=kmax,
                      dmin=np.asarray(dmin), dmax=np.asarray(dmax))
