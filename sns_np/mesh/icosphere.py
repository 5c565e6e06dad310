"""Subdivided icosahedra on the unit sphere."""

from __future__ import annotations

import numpy as np

from .._validation import check_positive_int

__all__ = ["icosphere"]


def _icosahedron():
    t = (1.0 + 5.0 ** 0.5) / 2.0
    V = np.array([
        [-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
        [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
        [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1],
    ], dtype=np.float64)
    F = np.array([
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ], dtype=np.int64)
    return V / np.linalg.norm(V, axis=1, keepdims=True), F


def icosphere(level: int = 3):
    """Unit icosphere: the icosahedron split ``level`` times, new vertices projected to the sphere.

    Parameters
    ----------
    level : int >= 0
        Subdivision level; the mesh has ``10 * 4**level + 2`` vertices and ``20 * 4**level``
        faces (level 4: 2,562 vertices; level 6: 40,962).

    Returns
    -------
    V : (n, 3) float array, unit vectors
    F : (m, 3) int array, counter-clockwise seen from outside (``det[a, b, c] > 0``)

    Examples
    --------
    >>> V, F = icosphere(2)
    >>> V.shape, F.shape
    ((162, 3), (320, 3))
    """
    level = check_positive_int(level, "level", minimum=0)
    if level > 9:
        raise ValueError(f"level must be <= 9 (2.6 million vertices), got {level}")
    V, F = _icosahedron()
    for _ in range(level):
        nv = V.shape[0]
        # one new vertex per undirected edge, numbered after the old vertices
        E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        E.sort(axis=1)
        key = E[:, 0] * nv + E[:, 1]
        uniq, inv = np.unique(key, return_inverse=True)
        a, b = uniq // nv, uniq % nv
        mid = V[a] + V[b]
        V = np.vstack([V, mid / np.linalg.norm(mid, axis=1, keepdims=True)])
        m = F.shape[0]
        e01, e12, e20 = (nv + inv[:m], nv + inv[m:2 * m], nv + inv[2 * m:])
        F = np.concatenate([
            np.stack([F[:, 0], e01, e20], axis=1),
            np.stack([F[:, 1], e12, e01], axis=1),
            np.stack([F[:, 2], e20, e12], axis=1),
            np.stack([e01, e12, e20], axis=1),
        ])
    return V, F
