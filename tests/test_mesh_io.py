import numpy as np
import pytest

from sns_np.mesh import MeshError, MeshFileError, check, icosphere, load, write_mesh

# spot_* and uv_sphere carry texture coordinates; counts from shared/data/meshes/README.md
SHARED = {
    "spot_triangulated.obj": (2930, 5856, 0),
    "spot_quadrangulated.obj": (2930, 5856, 2928),
    "spot_control_mesh.obj": (188, 372, 176),
    "max10606.obj": (10606, 21208, 0),
    "decimated_max.obj": (5272, 10540, 0),
    "armadillo21622.obj": (21622, 43240, 0),
    "flower_mesh3.obj": (642, 1280, 0),
    "flower_mesh5.obj": (10242, 20480, 0),
    "icosphere2.obj": (162, 320, 0),
    "icosphere3.obj": (642, 1280, 0),
    "uv_sphere.obj": (382, 760, 0),
}


def _write(path, text):
    path.write_text(text)
    return path


def test_obj_with_texture_normals_and_negative_indices(tmp_path):
    V, F = icosphere(1)
    lines = [f"v {x} {y} {z}" for x, y, z in V]
    lines += [f"vt {i / 50} 0.5" for i in range(len(V))] + ["vn 0 0 1"]
    for a, b, c in F[:-1]:
        lines.append(f"f {a + 1}/{a + 1}/1 {b + 1}/{b + 1}/1 {c + 1}//1")
    a, b, c = F[-1] - len(V)                        # negative (relative) indices
    lines.append(f"f {a} {b} {c}")
    V2, F2, rep = load(_write(tmp_path / "m.obj", "\n".join(lines) + "\n"), return_report=True)
    np.testing.assert_array_equal(F2, F)
    np.testing.assert_allclose(V2, V)
    assert not rep.changed and rep.n_vertices == 42


def test_polygons_are_triangulated_with_the_best_fan(tmp_path):
    # a cube of quads: 6 quads -> 12 triangles, closed, genus 0
    text = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
            "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n")
    V, F, rep = load(_write(tmp_path / "cube.obj", text), return_report=True)
    assert F.shape == (12, 3) and rep.n_polygons_triangulated == 6
    assert check(V, F).volume == pytest.approx(1.0)


def test_pentagon_fan_avoids_slivers(tmp_path):
    # a flat pentagon whose first corner sees a nearly collinear fan: the chosen apex differs
    pts = np.array([[0, 0, 0], [1, -0.001, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], dtype=float)
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in pts) + "f 2 3 4 5 1\n"
    V, F = load(_write(tmp_path / "penta.obj", text))
    from sns_np.mesh import face_angles
    assert np.degrees(face_angles(V, F).min()) > 10


def test_seam_duplicates_are_merged(tmp_path):
    # split an icosphere along the edges of vertex 0: duplicate vertex 0 for half of its faces
    V, F = icosphere(1)
    F = F.copy()
    fan = np.flatnonzero((F == 0).any(axis=1))[:3]
    F[fan] = np.where(F[fan] == 0, len(V), F[fan])
    V2 = np.vstack([V, V[:1]])
    path = tmp_path / "seam.obj"
    write_mesh(path, V2, F)
    Vl, Fl, rep = load(path, return_report=True)
    assert rep.n_vertices_merged == 1 and Vl.shape == (42, 3)
    check(Vl, Fl)
    # without merging the seam stays open
    Vn, Fn = load(path, merge=False)
    assert Vn.shape == (43, 3)


def test_coincident_vertices_of_a_closed_mesh_stay_apart(tmp_path):
    # "auto" merges only when that closes boundary edges
    V, F = icosphere(1)
    V = np.vstack([V, V[5]])                        # an unreferenced copy of vertex 5
    path = tmp_path / "dup.obj"
    _write(path, "".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in V)
           + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    _, F2, rep = load(path, return_report=True)
    assert rep.n_vertices_merged == 0 and rep.n_unreferenced_dropped == 1
    np.testing.assert_array_equal(F2, F)


def test_unreferenced_vertices_are_dropped_keeping_order(tmp_path):
    text = ("v 9 9 9\nv 1 1 1\nv 1 -1 -1\nv 7 7 7\nv -1 1 -1\nv -1 -1 1\n"
            "f 2 3 5\nf 2 5 6\nf 2 6 3\nf 3 6 5\n")
    V, F, rep = load(_write(tmp_path / "t.obj", text), return_report=True)
    assert rep.n_unreferenced_dropped == 2
    np.testing.assert_array_equal(V[0], [1, 1, 1])
    check(V, F)


def test_off_with_polygons_and_comments(tmp_path):
    text = ("OFF\n# a cube\n8 6 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n"
            "4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n")
    V, F = load(_write(tmp_path / "cube.off", text))
    assert check(V, F).volume == pytest.approx(1.0)


def test_ply_with_quads(tmp_path):
    pytest.importorskip("meshio")
    head = ("ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\n"
            "property float z\nelement face 6\nproperty list uchar int vertex_indices\n"
            "end_header\n")
    body = ("0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n"
            "4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n")
    V, F, rep = load(_write(tmp_path / "cube.ply", head + body), return_report=True)
    assert F.shape == (12, 3) and rep.n_polygons_triangulated == 6
    assert check(V, F).volume == pytest.approx(1.0)


@pytest.mark.parametrize("ext", [".ply", ".stl", ".off", ".obj", ".vtu"])
def test_round_trip_through_formats(tmp_path, ext):
    V, F = icosphere(2)
    path = tmp_path / f"ico{ext}"
    write_mesh(path, V, F)
    if ext == ".vtu":
        with pytest.raises(MeshFileError, match="unsupported mesh format"):
            load(path)
        return
    V2, F2, rep = load(path, return_report=True)
    assert V2.shape == V.shape and F2.shape == F.shape
    check(V2, F2)
    from scipy.spatial import cKDTree
    assert cKDTree(V).query(V2)[0].max() < 1e-6     # STL stores float32 and may reorder
    assert rep.n_vertices == 162


def test_stl_soup_is_merged(tmp_path):
    pytest.importorskip("trimesh")
    import trimesh

    V, F = icosphere(1)
    path = tmp_path / "soup.stl"
    trimesh.Trimesh(V, F, process=False).export(path)
    V2, F2 = load(path)
    assert V2.shape == (42, 3)
    check(V2, F2)


def test_write_with_point_data(tmp_path):
    meshio = pytest.importorskip("meshio")
    V, F = icosphere(1)
    write_mesh(tmp_path / "d.ply", V, F, {"H": np.ones(len(V))})
    assert "H" in meshio.read(tmp_path / "d.ply").point_data
    with pytest.raises(ValueError, match="cannot store per-vertex fields"):
        write_mesh(tmp_path / "d.obj", V, F, {"H": np.ones(len(V))})
    with pytest.raises(ValueError, match="point field 'H'"):
        write_mesh(tmp_path / "d.vtu", V, F, {"H": np.ones(3)})


def test_errors_name_the_file(tmp_path):
    with pytest.raises(MeshFileError, match="nope.obj' not found"):
        load(tmp_path / "nope.obj")
    with pytest.raises(MeshFileError, match="unsupported mesh format '.xyz'"):
        load(_write(tmp_path / "a.xyz", "1 2 3\n"))
    with pytest.raises(MeshFileError, match="empty mesh"):
        load(_write(tmp_path / "empty.obj", "# nothing\n"))
    with pytest.raises(MeshFileError, match="vertex 1 has non-finite"):
        load(_write(tmp_path / "nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"))
    with pytest.raises(MeshFileError, match="refers to vertex 5"):
        load(_write(tmp_path / "idx.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 6\n"))
    with pytest.raises(MeshFileError, match="cannot parse face"):
        load(_write(tmp_path / "bad.obj", "v 0 0 0\nf a b c\n"))
    with pytest.raises(MeshFileError, match="not an OFF file"):
        load(_write(tmp_path / "bad.off", "PLY\n"))
    with pytest.raises(MeshFileError, match="cannot read mesh file .*junk.ply"):
        load(_write(tmp_path / "junk.ply", "this is not a ply file\n"))
    with pytest.raises(ValueError, match="merge must be"):
        load(tmp_path / "x.obj", merge="yes")
    assert issubclass(MeshFileError, MeshError)


@pytest.mark.data
@pytest.mark.parametrize("name", sorted(SHARED))
def test_shared_meshes_load_with_documented_counts(mesh_dir, name):
    n, m, n_poly = SHARED[name]
    V, F, rep = load(mesh_dir / name, return_report=True)
    assert (V.shape[0], F.shape[0], rep.n_polygons_triangulated) == (n, m, n_poly)
    assert rep.n_vertices_merged == 0 and rep.n_unreferenced_dropped == 0
    assert check(V, F).euler_characteristic == 2


@pytest.mark.data
def test_spot_quads_share_the_triangulated_positions(mesh_dir):
    Vt, _ = load(mesh_dir / "spot_triangulated.obj")
    Vq, _ = load(mesh_dir / "spot_quadrangulated.obj")
    np.testing.assert_array_equal(Vt, Vq)
