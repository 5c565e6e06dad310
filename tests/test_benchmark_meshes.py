"""The meshes benchmarks/cad_shapes.py builds, and the closed form they are scored against."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from sns_np.mesh import check

_spec = importlib.util.spec_from_file_location(
    "cad_shapes", Path(__file__).resolve().parents[1] / "benchmarks" / "cad_shapes.py")
cad_shapes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cad_shapes)

#: closed-form volumes: the cube [-1, 1]^3, seven unit voxels, the 96-gon prism of radius 1
VOLUMES = {"cube": 8.0, "jack": 7.0, "jack_coarse": 7.0,
           "cylinder": 0.5 * 96 * np.sin(2 * np.pi / 96) * 2.5}


@pytest.mark.parametrize("name", cad_shapes.CAD)
def test_cad_mesh_is_closed_genus0_and_outward(name):
    V, F = cad_shapes.cad_mesh(name)
    check(V, F)                         # closed, manifold, genus 0, or it raises
    T = V[F]
    volume = np.einsum("ij,ij->i", T[:, 0], np.cross(T[:, 1], T[:, 2])).sum() / 6
    assert volume == pytest.approx(VOLUMES[name], rel=1e-12)     # positive: outward


@pytest.mark.parametrize("name", cad_shapes.CAD)
def test_exact_normals_match_the_flat_faces(name):
    V, F = cad_shapes.cad_mesh(name)
    T = V[F]
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    inside, n_true, H_true = cad_shapes.exact_away_from_edges(name, T.mean(axis=1), 0.05)
    assert inside.mean() > 0.5
    flat = inside & (H_true == 0)
    assert flat.sum() > 100
    np.testing.assert_allclose(n[flat], n_true[flat], atol=1e-12)
    if name == "cylinder":      # the side: a chord's normal, within one segment's angle
        side = inside & (H_true > 0)
        cos = np.einsum("ij,ij->i", n[side], n_true[side])
        assert cos.min() > np.cos(2 * np.pi / 96)
        assert np.all(H_true[side] == 0.5)


def test_edges_are_excluded():
    # points on an edge, and just inside it, of each polycube: never "away from the edges"
    x = np.array([[1.0, 1.0, 0.3], [1.0, 0.95, 0.3], [1.0, 0.5, 0.3]])
    inside, n, _ = cad_shapes.exact_away_from_edges("cube", x, 0.1)
    assert inside.tolist() == [False, False, True]
    np.testing.assert_array_equal(n[2], [1.0, 0.0, 0.0])
    # the jack's concave edge between the +x and +y arms, and a point on the +y arm's +x face
    x = np.array([[0.5, 0.5, 0.1], [0.5, 1.0, 0.1]])
    inside, n, _ = cad_shapes.exact_away_from_edges("jack", x, 0.1)
    assert inside.tolist() == [False, True]
    np.testing.assert_array_equal(n[1], [1.0, 0.0, 0.0])
