"""Closest points on a mesh (sns_np.mesh.closest) against a brute-force search."""

import numpy as np
import pytest

from sns_np.mesh import icosphere
from sns_np.mesh.closest import ClosestPoint, _closest_on_triangle
from sns_np.mesh.equalise import _subtriangle_centroids


def _grid_distance(x, T, m=120):
    """Distance from x to triangle T (3, 3) by a barycentric grid of step 1/m (an upper
    bound within m^-1 times the longest edge of the truth)."""
    i, j = np.meshgrid(np.arange(m + 1), np.arange(m + 1), indexing="ij")
    keep = i + j <= m
    a, b = i[keep] / m, j[keep] / m
    P = (1 - a - b)[:, None] * T[0] + a[:, None] * T[1] + b[:, None] * T[2]
    return np.linalg.norm(P - x, axis=1).min()


def test_closest_on_triangle_matches_a_fine_grid():
    g = np.random.default_rng(0)
    for _ in range(200):
        T = g.standard_normal((3, 3))
        x = 2.0 * g.standard_normal(3)           # every Voronoi region gets points
        u, v, w = _closest_on_triangle(x, T[0], T[1], T[2])
        assert min(u, v, w) >= -1e-12 and abs(u + v + w - 1.0) < 1e-12
        d = np.linalg.norm(u * T[0] + v * T[1] + w * T[2] - x)
        edge = np.linalg.norm(T - np.roll(T, 1, axis=0), axis=1).max()
        ref = _grid_distance(x, T)
        assert ref - edge / 120 - 1e-12 <= d <= ref + 1e-12


def test_subdivision_centroids_are_the_pieces_centroids():
    for level in range(4):
        beta = _subtriangle_centroids(2 ** level)
        assert beta.shape == (4 ** level, 3)
        assert np.allclose(beta.sum(axis=1), 1.0) and (beta > 0).all()
        assert len(np.unique(np.round(beta, 12), axis=0)) == 4 ** level
        assert np.allclose(beta.mean(axis=0), 1 / 3)      # equal pieces tile the triangle


@pytest.fixture(scope="module")
def bumpy():
    """An irregular closed mesh: an icosphere with noisy radii and a few long faces."""
    V, F = icosphere(2)
    g = np.random.default_rng(1)
    V = V * (1.0 + 0.15 * g.random(len(V)))[:, None] * np.array([1.0, 0.6, 1.8])
    return V, F


def _brute(X, V, F):
    d = np.full(len(X), np.inf)
    for f in F:
        for i, x in enumerate(X):
            u, v, w = _closest_on_triangle(x, V[f[0]], V[f[1]], V[f[2]])
            d[i] = min(d[i], np.linalg.norm(u * V[f[0]] + v * V[f[1]] + w * V[f[2]] - x))
    return d


def test_query_is_exact_near_and_far(bumpy):
    V, F = bumpy
    g = np.random.default_rng(2)
    near = V[g.integers(0, len(V), 150)] + 0.05 * g.standard_normal((150, 3))
    far = 3.0 * g.standard_normal((150, 3))
    X = np.concatenate([near, far])
    C = ClosestPoint(V, F, k=2)                  # few proposals: the fallback must work
    face, beta, d = C.query(X)
    assert np.allclose(d, _brute(X, V, F), rtol=0, atol=1e-12)
    P = np.einsum("nc,nci->ni", beta, V[F[face]])
    assert np.allclose(np.linalg.norm(P - X, axis=1), d, atol=1e-12)


def test_inexact_query_is_an_upper_bound_and_mostly_exact(bumpy):
    V, F = bumpy
    g = np.random.default_rng(3)
    X = V[g.integers(0, len(V), 300)] + 0.02 * g.standard_normal((300, 3))
    _, _, d = ClosestPoint(V, F).query(X, exact=False)
    truth = _brute(X, V, F)
    assert (d >= truth - 1e-12).all()
    assert np.mean(d > truth + 1e-12) < 0.05


def test_points_on_the_mesh_have_distance_zero(bumpy):
    V, F = bumpy
    face, beta, d = ClosestPoint(V, F).query(V)
    assert np.abs(d).max() < 1e-12
    assert np.allclose(np.einsum("nc,nci->ni", beta, V[F[face]]), V, atol=1e-12)


@pytest.mark.parametrize("X, match", [(np.zeros((4, 2)), r"shape \(n, 3\)"),
                                      (np.array([[0.0, np.nan, 0.0]]), "NaN")])
def test_bad_queries_are_named(bumpy, X, match):
    with pytest.raises(ValueError, match=match):
        ClosestPoint(*bumpy).query(X)
