import numpy as np
import pytest

from sns_np.mesh import (
    MeshError,
    MeshFileError,
    MeshRepairWarning,
    check,
    icosphere,
    load,
    write_mesh,
)

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


# ------------------------------------------------------------------ crafted and polygon files
# (issue 13: every malformed file gives a MeshFileError naming the file and the line/element)

_PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
             "property float z\nelement face {nf}\nproperty list uchar int vertex_indices\n"
             "end_header\n")
_TET_V = "1 1 1\n1 -1 -1\n-1 1 -1\n-1 -1 1\n"
_TET_F = "3 0 1 2\n3 0 2 3\n3 0 3 1\n3 1 3 2\n"


def _polygon_obj(path, xy, z=None):
    z = np.zeros(len(xy)) if z is None else z
    text = "".join(f"v {x:.17g} {y:.17g} {w:.17g}\n" for (x, y), w in zip(xy, z))
    return _write(path, text + "f " + " ".join(str(i + 1) for i in range(len(xy))) + "\n")


def _assert_fold_free(V, F, area):
    """All triangles turn the polygon's way (+z) and together cover its area exactly once."""
    t = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])[:, 2] / 2
    assert np.all(t > 0)
    assert t.sum() == pytest.approx(area, rel=1e-9)


def _shoelace(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_nonconvex_quad_takes_its_interior_diagonal(tmp_path):
    # an arrowhead: the fan from corner 1 (the old best-angle choice) folds over corner 2
    xy = np.array([[0, 0], [2, 0], [0.5, 0.5], [0, 2]], dtype=float)
    V, F = load(_polygon_obj(tmp_path / "arrow.obj", xy))
    _assert_fold_free(V, F, _shoelace(xy))


def test_nonconvex_polygon_is_ear_clipped_without_folds(tmp_path):
    # a comb with 12 teeth (50 corners): no fan works, ear clipping does
    teeth = []
    for i in range(12):
        teeth += [[2 * i, 1], [2 * i + 1, 5], [2 * i + 2, 1]]
    xy = np.array([[0, 0], [24, 0]] + teeth[::-1], dtype=float)
    xy = np.unique(xy, axis=0, return_index=True)[1]
    xy = np.array([[0, 0], [24, 0]] + teeth[::-1], dtype=float)[np.sort(xy)]
    V, F, rep = load(_polygon_obj(tmp_path / "comb.obj", xy), return_report=True)
    assert rep.n_polygons_triangulated == 1 and F.shape == (len(xy) - 2, 3)
    _assert_fold_free(V, F, _shoelace(xy))


@pytest.mark.parametrize("k", [1000, 10000])
def test_large_polygon_is_triangulated(tmp_path, k):
    # a star with k/2 reflex corners; issue 13 measured 12.7 s for 1,000 corners (quadratic
    # fans); ear clipping takes ~0.25 s for 10,000 (no timing asserted, STYLE.md 9)
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    r = np.where(np.arange(k) % 2 == 0, 1.0, 0.7)
    xy = np.stack([r * np.cos(t), r * np.sin(t)], axis=1)
    V, F = load(_polygon_obj(tmp_path / "star.obj", xy))
    assert F.shape == (k - 2, 3)
    _assert_fold_free(V, F, _shoelace(xy))


def test_self_crossing_polygons_are_reported(tmp_path):
    # no split of a bow tie or of a polygon with a crossing loop is fold-free: they are split
    # as fans (real meshes have such slivers) and the report and a warning say so
    for name, xy in [("bow.obj", [[0, 0], [1, 1], [1, 0], [0, 1]]),
                     ("loop.obj", [[0, 0], [3, 0], [3, 2], [1, -1], [0, 2], [-1, 1]]),
                     ("big.obj", [[np.cos(t), np.sin(t)] for t in np.linspace(0, 6, 12)]
                      + [[0.5, 0.5], [-2, 0.5]])]:
        path = _polygon_obj(tmp_path / name, np.array(xy, dtype=float))
        k = len(xy)
        V, F, rep = load(path, return_report=True)
        assert F.shape == (k - 2, 3) and rep.n_polygons_self_crossing == 1
        assert rep.self_crossing_example == f"{path}: line {k + 1}"
        with pytest.warns(MeshRepairWarning, match=rf"{name}: split 1 self-crossing polygon as "
                                                   rf"fans that may fold \(first at .*line"):
            load(path)


@pytest.mark.data
def test_spot_control_mesh_has_self_crossing_slivers(mesh_dir):
    # two quads and two pentagons of spot's control mesh cross themselves in their plane
    *_, rep = load(mesh_dir / "spot_control_mesh.obj", return_report=True)
    assert rep.n_polygons_self_crossing == 4


def test_obj_empty_face_and_index_zero_name_the_line(tmp_path):
    with pytest.raises(MeshFileError, match=r"e.obj: line 4: a face needs at least 3 corners, "
                                            r"got 0"):
        load(_write(tmp_path / "e.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf\nf 1 2 3\n"))
    with pytest.raises(MeshFileError, match=r"two.obj: line 4: a face needs at least 3"):
        load(_write(tmp_path / "two.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n"))
    with pytest.raises(MeshFileError, match=r"z.obj: line 4: vertex index 0 in a face; OBJ "
                                            r"indices start at 1"):
        load(_write(tmp_path / "z.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"))
    with pytest.raises(MeshFileError, match=r"r.obj: line 5: a face refers to vertex 3"):
        load(_write(tmp_path / "r.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n"))


def test_off_short_face_names_the_line(tmp_path):
    text = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n"
    with pytest.raises(MeshFileError, match=r"s.off: line 6: malformed face"):
        load(_write(tmp_path / "s.off", text))


def test_ply_counts_are_checked(tmp_path):
    # faces that use a vertex the header does not declare
    head = _PLY_HEAD.format(nv=3, nf=4)
    body = "1 1 1\n1 -1 -1\n-1 1 -1\n" + _TET_F
    with pytest.raises(MeshFileError, match=r"few.ply: face 1 \(line 14\) uses vertex 3, but "
                                            r"the 'vertex' element declares 3 vertices"):
        load(_write(tmp_path / "few.ply", head + body))
    # more faces declared than held
    with pytest.raises(MeshFileError, match=r"more.ply: the PLY header \(line 7\) declares 6 "
                                            r"'face' elements but the file holds only 4"):
        load(_write(tmp_path / "more.ply", _PLY_HEAD.format(nv=4, nf=6) + _TET_V + _TET_F))
    # fewer declared than held: the rest is refused too, not ignored
    with pytest.raises(MeshFileError, match=r"less.ply: line 17: data after the last element"):
        load(_write(tmp_path / "less.ply", _PLY_HEAD.format(nv=4, nf=3) + _TET_V + _TET_F))
    # a face list shorter than its count
    with pytest.raises(MeshFileError, match=r"short.ply: line 14: malformed 'face' element 0"):
        load(_write(tmp_path / "short.ply", _PLY_HEAD.format(nv=4, nf=4) + _TET_V
                    + "3 0 1\n" + _TET_F[8:]))
    V, F = load(_write(tmp_path / "ok.ply", _PLY_HEAD.format(nv=4, nf=4) + _TET_V + _TET_F))
    check(V, F)


def _binary_ply(nv, nf, V, F, order="<"):
    head = (f"ply\nformat binary_{'little' if order == '<' else 'big'}_endian 1.0\n"
            f"element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
    body = np.asarray(V, dtype=order + "f4").tobytes()
    for f in F:
        body += np.uint8(len(f)).tobytes() + np.asarray(f, dtype=order + "i4").tobytes()
    return head.encode() + body


@pytest.mark.parametrize("order", ["<", ">"])
def test_binary_ply(tmp_path, order):
    V0, F0 = icosphere(1)
    polys = F0.tolist()
    path = tmp_path / "b.ply"
    path.write_bytes(_binary_ply(len(V0), len(polys), V0, polys, order))
    V, F = load(path)
    np.testing.assert_array_equal(F, F0)
    np.testing.assert_allclose(V, V0, atol=1e-6)
    # a quad among the triangles takes the one-by-one path
    path.write_bytes(_binary_ply(4, 2, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                                 [[0, 1, 2, 3], [0, 3, 2]], order))
    assert load(path, merge=False)[1].shape == (3, 3)
    # a header that declares a billion faces in a 200-byte file
    path.write_bytes(_binary_ply(len(V0), 10**9, V0, polys[:2], order))
    with pytest.raises(MeshFileError, match=r"b.ply: the PLY header \(line 7\) declares "
                                            r"1000000000 'face' elements but the file holds "
                                            r"only 2"):
        load(path)


def test_load_warns_about_repairs(tmp_path):
    text = ("v 9 9 9\nv 1 1 1\nv 1 -1 -1\nv 7 7 7\nv -1 1 -1\nv -1 -1 1\n"
            "f 2 3 5\nf 2 5 6\nf 2 6 3\nf 3 6 5\n")
    path = _write(tmp_path / "t.obj", text)
    with pytest.warns(MeshRepairWarning, match=r"t.obj: dropped 2 unreferenced vertices"):
        load(path)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load(path, return_report=True)               # the report says it; no warning


def test_seam_merge_warns(tmp_path):
    V, F = icosphere(1)
    F = F.copy()
    fan = np.flatnonzero((F == 0).any(axis=1))[:3]
    F[fan] = np.where(F[fan] == 0, len(V), F[fan])
    path = tmp_path / "seam.obj"
    write_mesh(path, np.vstack([V, V[:1]]), F)
    with pytest.warns(MeshRepairWarning, match=r"merged 1 coincident vertex"):
        load(path)


# ------------------------------------------------------------------ property-based tests
hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_SETTINGS = settings(max_examples=60, deadline=None,
                     suppress_health_check=[HealthCheck.function_scoped_fixture])


@_SETTINGS
@given(k=st.integers(3, 300), seed=st.integers(0, 2**32 - 1))
def test_star_polygons_in_any_plane_are_fold_free(k, seed):
    # random star-shaped (so simple) polygons, rotated into a random plane
    from sns_np.mesh._polygons import triangulate
    g = np.random.default_rng(seed)
    t = np.sort(g.uniform(0, 2 * np.pi, k))
    gaps = np.diff(np.r_[t, t[0] + 2 * np.pi])
    if gaps.min() < 1e-3 or gaps.max() > 3.0:       # star-shaped about 0 needs gaps < pi
        return
    r = g.uniform(0.2, 1.0, k)
    P2 = np.stack([r * np.cos(t), r * np.sin(t)], axis=1)
    Q = np.linalg.qr(g.standard_normal((3, 3)))[0]
    V = np.c_[P2, np.zeros(k)] @ Q.T + g.standard_normal(3)
    F, _, crossed = triangulate(V, [list(range(k))])
    n = np.cross(Q[:, 0], Q[:, 1])                   # the polygon's normal in 3D
    assert crossed == []
    A = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]) @ n / 2
    assert F.shape == (k - 2, 3)
    assert np.all(A > -1e-12)
    assert A.sum() == pytest.approx(_shoelace(P2), rel=1e-9, abs=1e-12)


_LINES = st.sampled_from([
    "v 0 0 0", "v 1 0 0", "v 0 1 0", "v 0 0 1", "v 1 2", "v nan 0 0", "v a b c",
    "f", "f 1", "f 1 2", "f 1 2 3", "f 1 3 4", "f 0 1 2", "f -1 -2 -3", "f -9 1 2",
    "f 1/1 2/2 3/3", "f 1//1 x 3", "f 1 2 3 4", "f 1 2 99", "vt 0 1", "# c", "",
    "f 2 3 4 1 2", "f 1 1 1",
])


def _assert_clean_failure_or_mesh(path, time_limit=2.0):
    import time
    import warnings
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            V, F = load(path)
    except MeshFileError as exc:
        msg = str(exc)
        assert path.name in msg and "\n" not in msg
    else:
        assert V.ndim == 2 and V.shape[1] == 3 and F.ndim == 2 and F.shape[1] == 3
        assert F.min() >= 0 and F.max() < len(V)
    assert time.perf_counter() - t0 < time_limit


@_SETTINGS
@given(lines=st.lists(_LINES, max_size=30))
def test_generated_obj_files_fail_cleanly(tmp_path, lines):
    _assert_clean_failure_or_mesh(_write(tmp_path / "gen.obj", "\n".join(lines) + "\n"))


@_SETTINGS
@given(nv=st.integers(0, 8), nf=st.integers(0, 8), cut=st.integers(0, 400),
       junk=st.binary(max_size=20), binary=st.booleans())
def test_generated_ply_files_fail_cleanly(tmp_path, nv, nf, cut, junk, binary):
    V = [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]
    F = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]
    if binary:
        data = _binary_ply(nv, nf, V, F)
    else:
        data = (_PLY_HEAD.format(nv=nv, nf=nf) + _TET_V + _TET_F).encode()
    data = data[:len(data) - cut] + junk if cut else data + junk
    path = tmp_path / "gen.ply"
    path.write_bytes(data)
    _assert_clean_failure_or_mesh(path)
