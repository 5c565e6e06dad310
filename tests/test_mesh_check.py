import numpy as np
import pytest

from sns_np.errors import MeshError, ShapeError
from sns_np.mesh import (
    BoundaryError,
    DegenerateFaceError,
    DisconnectedError,
    DuplicateFaceError,
    GenusError,
    NonManifoldError,
    OrientationError,
    UnreferencedVertexError,
    check,
    icosphere,
    load,
)

from .test_mesh_helpers import ellipsoid, glued_at_vertex, tetrahedron, torus, two_spheres


def test_valid_meshes_pass():
    for V, F in [tetrahedron(), icosphere(0), icosphere(3), ellipsoid()]:
        s = check(V, F)
        assert s.euler_characteristic == 2
        assert s.n_vertices - s.n_edges + s.n_faces == 2
        assert s.volume > 0 and s.area > 0


def test_summary_values_on_icosphere():
    V, F = icosphere(2)
    s = check(V, F)
    assert (s.n_vertices, s.n_edges, s.n_faces) == (162, 480, 320)


def test_open_mesh_reports_boundary_edges():
    V, F = icosphere(2)
    with pytest.raises(BoundaryError, match="3 boundary edge") as e:
        check(V, F[1:])
    assert e.value.count == 3
    # removing a vertex's whole fan leaves an open mesh with an unreferenced vertex first
    keep = ~(F == 0).any(axis=1)
    with pytest.raises(UnreferencedVertexError) as e:
        check(V, F[keep])
    assert e.value.example == 0


def test_unreferenced_vertex():
    V, F = icosphere(1)
    with pytest.raises(UnreferencedVertexError, match="1 of 43 vertices") as e:
        check(np.vstack([V, [[5.0, 5.0, 5.0]]]), F)
    assert e.value.example == 42


def test_two_components():
    V, F = two_spheres()
    with pytest.raises(DisconnectedError, match="2 connected components") as e:
        check(V, F)
    assert e.value.count == 2


def test_pinched_vertex():
    V, F = glued_at_vertex()
    with pytest.raises(NonManifoldError, match="pinched") as e:
        check(V, F)
    assert e.value.count == 1


def test_non_manifold_edge():
    V, F = icosphere(1)
    a, b = F[0, 0], F[0, 1]
    # a fin: an extra triangle hanging from edge (a, b), closed off as a thin tetrahedron
    # would still leave that edge with three faces
    V2 = np.vstack([V, 1.5 * (V[a] + V[b]) / 2])
    F2 = np.vstack([F, [[b, a, len(V)]]])
    with pytest.raises(NonManifoldError, match="shared by more than two faces") as e:
        check(V2, F2)
    assert set(e.value.example) == {int(min(a, b)), int(max(a, b))}


def test_flipped_face_is_inconsistent():
    V, F = icosphere(2)
    F = F.copy()
    F[17] = F[17, ::-1]
    with pytest.raises(OrientationError, match="inconsistent winding") as e:
        check(V, F)
    assert e.value.count == 3
    # the example is the flipped face or one of its three edge neighbours
    shares_edge = (np.isin(F, F[17]).sum(axis=1) == 2)
    assert e.value.example == 17 or shares_edge[e.value.example]


def test_inward_mesh():
    V, F = icosphere(2)
    with pytest.raises(OrientationError, match="inwards"):
        check(V, F[:, ::-1])


def test_duplicate_face():
    V, F = icosphere(1)
    with pytest.raises(DuplicateFaceError, match="faces 3 and 80") as e:
        check(V, np.vstack([F, F[3, [1, 2, 0]]]))
    assert e.value.example == (3, 80)


def test_repeated_index_face():
    V, F = icosphere(1)
    F = F.copy()
    F[5, 2] = F[5, 0]
    with pytest.raises(DegenerateFaceError, match="repeat a vertex") as e:
        check(V, F)
    assert e.value.example == 5


def test_zero_area_face():
    V, F = icosphere(2)
    V = V.copy()
    a, b, c = F[10]
    V[a] = 0.5 * (V[b] + V[c])                   # collinear corners, topology untouched
    with pytest.raises(DegenerateFaceError, match="zero area") as e:
        check(V, F)
    assert e.value.example == 10


def test_torus_has_genus_one():
    V, F = torus()
    with pytest.raises(GenusError, match="genus 1") as e:
        check(V, F)
    assert e.value.count == 1


def test_errors_are_value_errors():
    for cls in (BoundaryError, GenusError, OrientationError):
        assert issubclass(cls, MeshError) and issubclass(cls, ValueError)


def test_bad_arrays():
    V, F = icosphere(1)
    with pytest.raises(ShapeError, match=r"shape \(m, 3\)"):
        check(V, F[:, :2])
    with pytest.raises(ShapeError, match="outside"):
        check(V, F + 1)
    with pytest.raises(ShapeError, match="non-finite"):
        check(np.where(np.arange(len(V))[:, None] == 3, np.nan, V), F)
    with pytest.raises(ShapeError, match="empty"):
        check(V, np.zeros((0, 3), dtype=int))


@pytest.mark.data
def test_shared_meshes_pass(mesh_dir):
    for path in sorted(mesh_dir.glob("*.obj")):
        V, F = load(path)
        assert check(V, F).euler_characteristic == 2, path.name
