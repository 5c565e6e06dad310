"""Array validation and edge bookkeeping shared by the mesh modules (private)."""

from __future__ import annotations

import numpy as np

from .._validation import as_points
from ..errors import ShapeError


def as_mesh(V, F, *, V_name: str = "V", F_name: str = "F"):
    """Validate a triangle mesh: ``V`` (n, 3) finite floats, ``F`` (m, 3) indices into ``V``.

    Returns C-contiguous float64 and int64 copies (or the inputs when already so).
    """
    V = as_points(V, V_name)
    F_arr = np.asarray(F)
    if F_arr.ndim != 2 or F_arr.shape[1] != 3:
        raise ShapeError(f"{F_name} must have shape (m, 3) (triangles), got {F_arr.shape}")
    if F_arr.size and not np.issubdtype(F_arr.dtype, np.integer):
        if not np.issubdtype(F_arr.dtype, np.floating) or np.any(F_arr != np.round(F_arr)):
            raise ShapeError(f"{F_name} must hold integer vertex indices, got dtype {F_arr.dtype}")
    F_arr = np.ascontiguousarray(F_arr, dtype=np.int64)
    if F_arr.shape[0] == 0:
        raise ShapeError(f"{F_name} is empty; expected at least one triangle")
    lo, hi = int(F_arr.min()), int(F_arr.max())
    if lo < 0 or hi >= V.shape[0]:
        bad = lo if lo < 0 else hi
        f = int(np.argwhere((F_arr < 0) | (F_arr >= V.shape[0]))[0, 0])
        raise ShapeError(
            f"{F_name} holds vertex index {bad} (face {f}) outside [0, {V.shape[0]}) for "
            f"{V_name} with {V.shape[0]} vertices"
        )
    return V, F_arr


def halfedges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tail and head of every halfedge; halfedge ``3 f + k`` runs ``F[f, k] -> F[f, k+1 mod 3]``."""
    tail = F.reshape(-1)
    head = F[:, [1, 2, 0]].reshape(-1)
    return tail, head


def unique_edges(F: np.ndarray, n: int):
    """Undirected edges of ``F``.

    Returns
    -------
    E : (e, 2) int array, ``E[:, 0] < E[:, 1]``
    h2e : (3 m,) int array, the undirected edge of each halfedge
    count : (e,) int array, number of halfedges on each edge
    """
    tail, head = halfedges(F)
    lo, hi = np.minimum(tail, head), np.maximum(tail, head)
    key = lo * np.int64(n) + hi
    ukey, h2e, count = np.unique(key, return_inverse=True, return_counts=True)
    E = np.stack([ukey // n, ukey % n], axis=1)
    return E, h2e.reshape(-1), count
