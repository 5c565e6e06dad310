"""The surface over a mesh whose normals follow its vertex normals (sns_np.mesh.heights),
and fit_mesh's "normals" target built on it."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sns_np.mesh import (
    NormalHeights,
    face_areas,
    face_normals,
    icosphere,
    midpoint_subdivision,
    subdivided_points,
    vertex_normals,
)
from sns_np.options import NORMAL_HEIGHT_TIE
from sns_np.shapes import Ellipsoid
from sns_np.surface import fit_mesh
from sns_np.surface._targets import _MeshTarget, normal_height_levels


def test_midpoint_subdivision_splits_every_edge_once_and_keeps_the_vertices_first():
    V, F = icosphere(1)
    V2, F2 = midpoint_subdivision(V, F, 1)
    assert len(V2) == len(V) + 3 * len(F) // 2 and len(F2) == 4 * len(F)
    assert np.array_equal(V2[:len(V)], V)
    # a closed mesh stays closed and genus 0: V - E + F = 2
    edges = {tuple(sorted(e)) for f in F2 for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    assert len(V2) - len(edges) + len(F2) == 2
    # the new vertices are midpoints, and the children keep their parent's orientation
    assert np.allclose(face_normals(V2, F2), np.tile(face_normals(V, F), (4, 1)), atol=1e-12)
    assert np.isclose(face_areas(V2, F2).sum(), face_areas(V, F).sum(), rtol=1e-12)


def test_midpoint_subdivision_carries_extra_columns_and_refuses_bad_levels():
    V, F = icosphere(0)
    data = np.hstack([V, np.arange(len(V), dtype=float)[:, None]])
    V2, F2 = midpoint_subdivision(data, F, 2)
    assert V2.shape[1] == 4
    # a linear function of the positions stays linear: the extra column is averaged alike
    lin = V @ [0.3, -1.0, 2.0]
    W2, _ = midpoint_subdivision(np.hstack([V, lin[:, None]]), F, 2)
    assert np.allclose(W2[:, 3], W2[:, :3] @ [0.3, -1.0, 2.0], atol=1e-12)
    for bad in (-1, 1.5):
        with pytest.raises(ValueError, match="levels must be an integer >= 0"):
            midpoint_subdivision(V, F, bad)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 79), st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
       st.integers(0, 3))
def test_subdivided_points_are_the_same_points(face, w, levels):
    V, F = icosphere(1)
    w = np.asarray(w) + 1e-9
    beta = (w / w.sum())[None, :]
    V2, F2 = midpoint_subdivision(V, F, levels)
    f2, b2 = subdivided_points([face], beta, len(F), levels)
    assert np.allclose(b2 @ V2[F2[f2[0]]], beta @ V[F[face]], atol=1e-12)
    assert (b2 >= 0).all() and np.isclose(b2.sum(), 1.0)


def test_subdivided_points_at_the_corners_and_midpoints():
    V, F = icosphere(0)
    beta = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0.5, 0.5, 0], [0, 0.5, 0.5]])
    face = np.zeros(len(beta), dtype=int)
    V2, F2 = midpoint_subdivision(V, F, 2)
    f2, b2 = subdivided_points(face, beta, len(F), 2)
    assert np.allclose(np.einsum("kc,kci->ki", b2, V2[F2[f2]]), beta @ V[F[0]], atol=1e-12)


def _energy(H, V, F, N, h):
    """The heights' least-squares objective, written out face by face:
    sum_f A_f |grad h + t|^2 + eps sum_vertices h^2 (t the face-wise part of the centre
    normal)."""
    VN, F2 = midpoint_subdivision(np.hstack([V, N]), F, H.levels)
    V2, N2 = VN[:, :3], VN[:, 3:]
    nf, A = face_normals(V2, F2), face_areas(V2, F2)
    nc = N2[F2].mean(axis=1)
    nc /= np.linalg.norm(nc, axis=1, keepdims=True)
    t = nc - (nc * nf).sum(axis=1, keepdims=True) * nf
    grad = np.zeros_like(t)
    for i in range(3):          # grad phi_i = nf x (edge opposite i) / (2 A)
        e = V2[F2[:, (i + 2) % 3]] - V2[F2[:, (i + 1) % 3]]
        grad += h[F2[:, i], None] * np.cross(nf, e) / (2 * A[:, None])
    stiff = np.zeros(len(V2))   # diag of the stiffness matrix: sum_f A_f |grad phi_i|^2
    for i in range(3):
        e = V2[F2[:, (i + 2) % 3]] - V2[F2[:, (i + 1) % 3]]
        np.add.at(stiff, F2[:, i], (e * e).sum(axis=1) / (4 * A))
    eps = H.tie * stiff.mean()  # the tie, at the mesh's own vertices
    return float((A * ((grad + t) ** 2).sum(axis=1)).sum() + eps * (h[:len(V)] ** 2).sum())


@pytest.mark.parametrize("tie", [1e-6, 1e-3, 1e-1])
def test_the_heights_minimise_their_objective(tie):
    """Central differences of the objective along random directions vanish at h."""
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(1)
    N = vertex_normals(V, F)
    H = NormalHeights(V, F, N, levels=1, tie=tie)
    g = np.random.default_rng(0)
    for _ in range(3):
        v = g.standard_normal(len(H.h))
        s = 1e-3

        def slope(h):
            return (_energy(H, V, F, N, h + s * v) - _energy(H, V, F, N, h - s * v)) / (2 * s)

        assert abs(slope(H.h)) < 1e-7 * abs(slope(np.zeros_like(H.h)))
        assert _energy(H, V, F, N, H.h + s * v) > _energy(H, V, F, N, H.h)


def _angle_to_sphere(V, F):
    c = V[F].mean(axis=1)
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    cos = np.clip(np.einsum("ij,ij->i", face_normals(V, F), c), -1, 1)
    return float(np.degrees(np.arccos(cos)).mean())


def test_on_a_sphere_the_surface_is_round_and_its_normals_the_spheres():
    V, F = icosphere(2)
    H = NormalHeights(V, F, levels=2, tie=1e-6)
    V2, F2 = H.mesh()
    flat, _ = midpoint_subdivision(V, F, 2)
    assert _angle_to_sphere(V2, F2) < 0.1 * _angle_to_sphere(flat, F2)
    r, r_flat = np.linalg.norm(V2, axis=1), np.linalg.norm(flat, axis=1)
    assert r.std() < 0.15 * r_flat.std()
    # the heights at barycentric points are those of the displaced mesh there
    g = np.random.default_rng(1)
    face = g.integers(0, len(F), 50)
    beta = g.dirichlet(np.ones(3), 50)
    f2, b2 = subdivided_points(face, beta, len(F), 2)
    assert np.allclose(H(face, beta), np.einsum("kc,kc->k", b2, H.h[F2[f2]]), atol=1e-15)


def test_a_stronger_tie_keeps_the_surface_nearer_the_vertices():
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    at_vertices = [np.abs(NormalHeights(V, F, levels=1, tie=t).h[:len(V)]).mean()
                   for t in (1e-4, 1e-2, 1.0, 100.0)]
    assert all(a > b for a, b in zip(at_vertices, at_vertices[1:]))
    assert at_vertices[-1] < 1e-2 * at_vertices[0]


def test_on_a_mesh_of_an_ellipsoid_the_surface_is_nearer_the_ellipsoid():
    """The closed form: the surface at the default tie is several times nearer the ellipsoid
    the mesh samples than the triangles are, in position and in normal."""
    E = Ellipsoid(1.0, 1.3, 0.7)
    axes = np.array(E.axes)
    V, F = E.mesh(4)

    def errors(V2, F2):         # at the face centres: |implicit - 1| and the normal angle
        c = V2[F2].mean(axis=1)
        grad = c / axes ** 2
        grad /= np.linalg.norm(grad, axis=1, keepdims=True)
        cos = np.clip(np.einsum("ij,ij->i", face_normals(V2, F2), grad), -1, 1)
        return np.abs(np.sqrt(((c / axes) ** 2).sum(axis=1)) - 1).mean(), \
            np.degrees(np.arccos(cos)).mean()

    d_flat, a_flat = errors(*midpoint_subdivision(V, F, 2))
    d, a = errors(*NormalHeights(V, F, levels=2, tie=NORMAL_HEIGHT_TIE).mesh())
    assert d < d_flat / 4 and a < a_flat / 10


@pytest.mark.parametrize("kw, match", [
    ({"levels": -1}, "levels must be an integer in"), ({"levels": 7}, "levels must be"),
    ({"tie": -1.0}, "tie must be a finite number >= 0"), ({"tie": float("nan")}, "tie must"),
    ({"N": np.ones((3, 3))}, "N must have the shape of V")])
def test_bad_arguments_are_refused(kw, match):
    V, F = icosphere(1)
    with pytest.raises(ValueError, match=match):
        NormalHeights(V, F, **kw)


def test_levels_keep_the_unknowns_within_the_cap():
    from sns_np.options import NORMAL_HEIGHT_LEVELS, NORMAL_HEIGHT_UNKNOWNS
    for n in (12, 2930, 10606, 21622, 100_000, 500_000):
        m = 2 * n - 4
        k = normal_height_levels(n, m)
        assert 0 <= k <= NORMAL_HEIGHT_LEVELS
        unknowns = n + sum(3 * (4 ** j) * m // 2 for j in range(k))
        assert k == 0 or unknowns <= NORMAL_HEIGHT_UNKNOWNS
        more = unknowns + 3 * (4 ** k) * m // 2
        assert k == NORMAL_HEIGHT_LEVELS or more > NORMAL_HEIGHT_UNKNOWNS


# ------------------------------------------------------------------- fit_mesh's targets

def _target(V, F, **kw):
    Vs = V / np.linalg.norm(V, axis=1, keepdims=True)
    return _MeshTarget(V, F, Vs, verbose=False, crease_angle="auto", **kw)


def test_the_normals_target_is_chosen_by_name_and_known_to_a_checkpoint():
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(3)
    normals = _target(V, F, smooth="normals")
    assert normals.heights.tie == NORMAL_HEIGHT_TIE and normals.crease_angle is None
    assert "round(s) of midpoint subdivision" in normals.smooth_why
    phong = _target(V, F, smooth="phong")
    assert phong.heights is None and phong.smooth_why.startswith("the Phong tessellation")
    assert phong.fingerprint != normals.fingerprint     # a checkpoint knows its targets
    assert normals.fingerprint == _target(V, F, smooth="normals").fingerprint


def test_the_normals_target_is_the_heights_surface_everywhere_it_is_drawn():
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(3)
    T = _target(V, F, smooth="normals")
    g = np.random.default_rng(3)
    face = g.integers(0, len(F), 200)
    beta = g.dirichlet(np.ones(3), 200)
    q, n = T._targets(face, beta)
    flat, n_flat = T.corr.to_mesh(face, beta)
    assert np.allclose(T.center + T.scale * q, flat + T.heights(face, beta)[:, None] * n_flat)
    # at the vertices the vertex draw and the face draw agree
    p, qv, nv = T.sample_vertices(50, np.random.default_rng(4))
    i = np.random.default_rng(4).integers(0, len(V), 50)      # the vertices it drew
    corner = np.array([np.flatnonzero((F == k).any(axis=1))[0] for k in i])
    qf, nf = T._targets(corner, (F[corner] == i[:, None]).astype(float))
    assert np.allclose(qv, qf, atol=1e-13) and np.allclose(nv, nf, atol=1e-13)
    # and the targets lie nearer the ellipsoid than the flat triangles
    E = Ellipsoid(1.0, 1.3, 0.7)
    x = T.center + T.scale * q

    def off(y):                 # |implicit - 1| of the ellipsoid, a first-order distance
        return np.abs(((y / np.array(E.axes)) ** 2).sum(axis=1) - 1).mean()

    assert off(x) < 0.5 * off(flat)


def test_normals_with_a_crease_angle_are_refused_before_the_embedding(monkeypatch):
    import sns_np.mesh as mesh

    def no_embedding(*a, **k):
        raise AssertionError("the embedding ran")

    monkeypatch.setattr(mesh, "spherical_embedding", no_embedding)
    V, F = icosphere(2)
    with pytest.raises(ValueError, match="keeps no creases; with creases=45.0"):
        fit_mesh(V, F, smooth="normals", creases=45, steps=2, progress=False)
    with pytest.raises(ValueError, match="unknown smooth 'loop'; expected one of"):
        fit_mesh(V, F, smooth="loop", steps=2, progress=False)


def test_fit_mesh_records_the_target_choice():
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(3)
    S, report = fit_mesh(V, F, smooth="normals", width=16, depth=1, steps=5, batch=128,
                         n_eval=200, progress=False)
    assert S.metadata["smooth"] == "normals" == report.choices["smooth"]["value"]
    assert "round(s) of midpoint subdivision" in report.choices["smooth"]["why"]
    assert report.choices["creases"]["value"] is None
    S, report = fit_mesh(V, F, width=16, depth=1, steps=5, batch=128, n_eval=200,
                         progress=False)
    assert S.metadata["smooth"] == "phong" == report.choices["smooth"]["value"]
