"""Mesh curvature baselines, for comparison with curvatures computed on a neural surface.

Sign convention (DESIGN.md): with outward normals, convex surfaces have positive curvature; the
unit sphere has ``H = K = 1`` and principal curvatures ``(1, 1)``; ``H = (kmin + kmax) / 2``
and ``K = kmin kmax`` whenever both come from one fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._arrays import as_mesh
from .operators import cotan_laplacian, face_angles, mass_matrix, vertex_normals

__all__ = ["Curvatures", "baseline_curvatures", "discrete_curvatures"]


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
