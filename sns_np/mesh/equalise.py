"""Area balancing of a spherical embedding by a density-equalising flow.

A conformal embedding shrinks protruding parts (limbs, ears) exponentially: the armadillo's
fingers get ``e^-27`` of their fair share of the sphere, far too little for a network to fit.
:func:`equalise_areas` moves the embedded vertices with the diffusion flow of Gastner & Newman
(2004), carried to the sphere as in Lyu, Lui & Choi (2024): the density
``rho = (surface area share) / (sphere area share)`` evolves by the heat equation
``rho_t = Delta rho`` on the sphere, and every point moves with velocity ``v = -grad rho / rho``;
the flow transports the initial density to a uniform one, so that in the limit every triangle's
sphere area is proportional to its surface area. Raising the initial density to a power
``strength`` in ``[0, 1]`` stops half-way: final sphere areas ``s = s_0^(1-strength)
A^strength`` (0: the conformal map unchanged; 1: area-preserving).

Discretisation (ours): the density lives on a fixed icosphere grid (not on the embedded mesh,
whose triangles may be tiny or badly shaped), where implicit Euler steps
``(M_g - dt L_g) rho^{k+1} = M_g rho^k`` use cached factorisations; the surface mass of each
mesh triangle is deposited at quadrature points on its spherical image. Vertices are advected by
the grid velocity, interpolated linearly. Each step is limited so that ``dt |grad v| <= 1/4``
on every grid triangle, which keeps the displacement a small perturbation of the identity, and a
step that would fold a triangle is halved and retried, so the embedding stays fold-free.

References
----------
M. T. Gastner and M. E. J. Newman, "Diffusion-based method for producing density-equalizing
maps", PNAS 101(20), 2004.

Z. Lyu, L. M. Lui and G. P. T. Choi, "Spherical density-equalizing map for genus-0 closed
surfaces", arXiv:2401.11795, 2024.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from .foldrepair import FoldRepair
from .icosphere import icosphere
from .operators import cotan_laplacian, face_areas, mass_matrix
from .spherical import SphereLocator, orientation_determinants, spherical_triangle_areas

__all__ = ["equalise_areas"]


def _face_gradient_basis(X, F):
    """Per-face vectors g_k with grad f = sum_k f[F[:, k]] g_k (piecewise linear f)."""
    P = X[F]
    N = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    dbl = np.linalg.norm(N, axis=1)
    n = N / dbl[:, None]
    G = np.stack([np.cross(n, P[:, (k + 2) % 3] - P[:, (k + 1) % 3]) for k in range(3)], axis=1)
    return G / dbl[:, None, None], 0.5 * dbl


class _Grid:
    """Fixed icosphere on which the density diffuses."""

    def __init__(self, level):
        self.V, self.F = icosphere(level)
        self.L = cotan_laplacian(self.V, self.F).tocsc()
        self.M = mass_matrix(self.V, self.F, "barycentric")
        self.m = self.M.diagonal()
        self.G, self.A = _face_gradient_basis(self.V, self.F)
        self.locator = SphereLocator(self.V, self.F)
        self._lu = {}

    def diffuse(self, rho, dt):
        if dt not in self._lu:
            system = (self.M - dt * self.L).tocsc()
            self._lu[dt] = spla.splu(system, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                                     options={"SymmetricMode": True})
        return self._lu[dt].solve(self.m * rho)

    def gradient(self, f):
        """Per-face gradient (k, 3) of vertex values f (n,) or per-face Jacobian of f (n, 3)."""
        if f.ndim == 1:
            return np.einsum("fk,fkd->fd", f[self.F], self.G)
        return np.einsum("fkc,fkd->fcd", f[self.F], self.G)

    def velocity(self, rho):
        """Vertex velocities -grad rho / rho (area-averaged face gradients, tangent)."""
        gf = self.gradient(rho) * self.A[:, None]
        g = np.zeros_like(self.V)
        for k in range(3):
            np.add.at(g, self.F[:, k], gf)
        g /= np.bincount(self.F.ravel(), weights=np.repeat(self.A, 3),
                         minlength=self.V.shape[0])[:, None]
        v = -g / rho[:, None]
        return v - np.einsum("ij,ij->i", v, self.V)[:, None] * self.V


def _subtriangle_centroids(r):
    """Barycentric centroids of the r^2 sub-triangles of a triangle split r times per side."""
    pts = []
    for i in range(r):
        for j in range(r - i):
            pts.append(((i + 1 / 3) / r, (j + 1 / 3) / r))
            if i + j < r - 1:
                pts.append(((i + 2 / 3) / r, (j + 2 / 3) / r))
    return np.array([[1 - x - y, x, y] for x, y in pts])


def _deposit(grid, Vs, F, mass, s):
    """Grid density of the masses of the spherical triangles.

    Each triangle's mass is spread over quadrature points spaced at most half a grid cell apart
    (so that no grid node inside a large triangle is left empty) and then to the nodes of the
    grid triangle containing each point, with its barycentric weights.
    """
    cell = 4 * np.pi / grid.F.shape[0]
    r = np.maximum(1, np.ceil(2.0 * np.sqrt(s / cell))).astype(np.int64)
    Q, w = [], []
    for rk in np.unique(r):
        idx = np.flatnonzero(r == rk)
        B = _subtriangle_centroids(int(rk))
        Q.append(np.einsum("qk,fkd->fqd", B, Vs[F[idx]]).reshape(-1, 3))
        w.append(np.repeat(mass[idx] / B.shape[0], B.shape[0]))
    Q, w = np.concatenate(Q), np.concatenate(w)
    Q /= np.linalg.norm(Q, axis=1, keepdims=True)
    face, beta = grid.locator.locate(Q)
    node = np.bincount(grid.F[face].ravel(), weights=(beta * w[:, None]).ravel(),
                       minlength=grid.V.shape[0])
    return node / grid.m


def equalise_areas(V, F, Vs, *, strength: float = 1.0, grid_level: int = 5,
                   t_end: float = 8.0, tol: float = 1e-3, max_steps: int = 2000,
                   repair=None):
    """Move a fold-free spherical embedding towards area preservation, keeping it fold-free.

    Parameters
    ----------
    V : (n, 3) float array, the surface
    F : (m, 3) int array
    Vs : (n, 3) float array, a fold-free spherical embedding of it
    strength : float in [0, 1]
        Fraction of the log area distortion to remove (1: equal areas, up to the grid).
    grid_level : int
        Icosphere level of the density grid (5: 10,242 nodes).
    t_end : float
        Diffusion time at which to stop (the density's slowest mode decays like
        ``exp(-2 t)``).
    tol : float
        Stop earlier once the grid density is uniform to ``max |rho - 1| < tol``.
    max_steps : int
    repair : FoldRepair or None
        Fold repair of this mesh, to reuse its cached weights (built when None).

    Returns
    -------
    Vs : (n, 3) float array, unit vectors, fold-free
    info : dict
        ``steps``, ``time`` (diffusion time reached), ``density_range`` (final ``max |rho - 1|``).

    References
    ----------
    M. T. Gastner and M. E. J. Newman, "Diffusion-based method for producing density-equalizing
    maps", PNAS 101(20), 2004.

    Z. Lyu, L. M. Lui and G. P. T. Choi, "Spherical density-equalizing map for genus-0 closed
    surfaces", arXiv:2401.11795, 2024.

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.mesh import icosphere
    >>> V, F = icosphere(3)
    >>> X = V * [1.0, 1.0, 3.0]                       # a cigar; its poles get crowded
    >>> Vs, info = equalise_areas(X, F, V, grid_level=3)
    >>> from sns_np.mesh.spherical import area_distortion
    >>> bool(area_distortion(X, F, Vs).std() < area_distortion(X, F, V).std())
    True
    """
    Vs = np.array(Vs, dtype=np.float64)
    grid = _Grid(grid_level)
    area = face_areas(V, F)
    s0 = spherical_triangle_areas(Vs, F)
    # density exponent: rho_0 = (A / s0)^strength, scaled to the grid's total area
    share = area / area.sum()
    mass = s0 * (share / (s0 / s0.sum())) ** strength
    mass *= grid.m.sum() / mass.sum()
    rho = _deposit(grid, Vs, F, mass, s0)
    face, beta = grid.locator.locate(Vs)
    if repair is None:
        repair = FoldRepair(V, F)
    t, step, dt_max, repairs = 0.0, 0, 0.05, 0
    dt = dt_max / 64
    while t < t_end and step < max_steps:
        if np.abs(rho - 1.0).max() < tol:
            break
        while True:
            new_rho = grid.diffuse(rho, dt)
            v = grid.velocity(new_rho)
            lip = np.sqrt((grid.gradient(v) ** 2).sum(axis=(1, 2))).max()
            if dt * lip > 0.25 and dt > 1e-9:
                dt /= 2
                continue
            vp = np.einsum("ik,ikd->id", beta, v[grid.F[face]])
            X = Vs + dt * vp
            X /= np.linalg.norm(X, axis=1, keepdims=True)
            bad = orientation_determinants(X, F) <= 0
            # a few folds (slivers bent by the piecewise-linear velocity) are repaired locally
            if not bad.any() or (bad.sum() <= max(10, F.shape[0] // 1000)
                                 and repair(X, max_rounds=8)[0] <= 8):
                break
            if dt <= 1e-9:
                return Vs, {"steps": step, "time": t, "density_range":
                            float(np.abs(rho - 1.0).max()), "stalled": True, "repairs": repairs}
            dt /= 2
        repairs += int(bad.any())
        Vs, rho, t, step = X, new_rho, t + dt, step + 1
        face, beta = grid.locator.locate(Vs)
        dt = min(2 * dt, dt_max)
    return Vs, {"steps": step, "time": t, "density_range": float(np.abs(rho - 1.0).max()),
                "stalled": False, "repairs": repairs}
