"""Tiny hand-built meshes for the mesh tests (no shared data needed), and a check of them."""

import numpy as np

from sns_np.mesh import icosphere


def tetrahedron():
    V = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])
    return V, F


def ellipsoid(level=3, axes=(1.0, 2.0, 3.0)):
    V, F = icosphere(level)
    return V * np.asarray(axes), F


def torus(n=12, m=8, R=2.0, r=0.7):
    """Outward-oriented torus: genus 1, Euler characteristic 0."""
    u, v = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    a, b = 2 * np.pi * u / n, 2 * np.pi * v / m
    V = np.stack([(R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a),
                  r * np.sin(b)], axis=-1).reshape(-1, 3)
    idx = lambda i, j: (i % n) * m + (j % m)
    F = []
    for i in range(n):
        for j in range(m):
            p, q, s, t = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            F += [[p, q, s], [p, s, t]]
    return V, np.array(F)


def two_spheres(shift=3.0, level=1):
    V, F = icosphere(level)
    return np.vstack([V, V + [shift, 0, 0]]), np.vstack([F, F + len(V)])


def glued_at_vertex(level=1):
    """Two icospheres sharing one vertex: a pinched (non-manifold) vertex."""
    V, F = icosphere(level)
    n = len(V)
    k = int(np.argmax(V[:, 0]))                      # rightmost vertex of sphere A
    W = -V + 2 * V[k]                                # mirrored copy touching A at V[k]
    j = k                                            # that same index in the copy sits at V[k]
    F2 = F[:, ::-1] + n                              # mirroring flips the orientation back
    F2 = np.where(F2 == j + n, k, F2)
    F2 = np.where(F2 > j + n, F2 - 1, F2)
    V2 = np.delete(W, j, axis=0)
    return np.vstack([V, V2]), np.vstack([F, F2])


def test_builders_have_the_intended_topology():
    from sns_np.mesh._arrays import unique_edges

    for (V, F), chi in [(tetrahedron(), 2), (ellipsoid(2), 2), (torus(), 0),
                        (two_spheres(), 4), (glued_at_vertex(), 3)]:
        E = unique_edges(F, len(V))[0]
        assert len(np.unique(F)) - len(E) + len(F) == chi
