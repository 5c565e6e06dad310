"""Crease-aware target normals: corner normals, the Phong tessellation they give, the gap
that makes "auto" choose them, and fit_mesh's ``creases`` option."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from sns_np.mesh import (
    Correspondence,
    corner_normals,
    face_normals,
    icosphere,
    normal_turn,
    vertex_normals,
)
from sns_np.options import COARSE_TURN, CREASE_ANGLE, CREASE_GAP
from sns_np.shapes import Bobble, Ellipsoid
from sns_np.surface import fit_mesh
from sns_np.surface._targets import coarseness, phong_gap

_spec = importlib.util.spec_from_file_location(
    "cad_shapes", Path(__file__).resolve().parents[1] / "benchmarks" / "cad_shapes.py")
cad_shapes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cad_shapes)


def cube(n):
    """The cube [-1, 1]^3, every face an n x n grid of squares split in two."""
    return cad_shapes._polycube([(0, 0, 0)], n, size=2.0)


def jack(n):
    return cad_shapes._polycube(cad_shapes.POLYCUBES["jack"][0], n)


@pytest.mark.parametrize("weighting", ["angle", "area"])
def test_without_creases_the_corners_carry_the_vertex_normals(weighting):
    V, F = cube(3)
    N = vertex_normals(V, F, weighting)[F]
    assert np.allclose(corner_normals(V, F, None, weighting), N, atol=1e-15)
    assert np.allclose(corner_normals(V, F, 180.0, weighting), N, atol=1e-15)
    # the cube's edges turn by 90 degrees: any angle above keeps the vertex normals
    assert np.allclose(corner_normals(V, F, 91.0, weighting), N, atol=1e-15)


def test_a_cube_with_creases_has_its_face_normals_at_every_corner():
    V, F = cube(3)
    Nc = corner_normals(V, F, 60.0)
    assert np.allclose(Nc, face_normals(V, F)[:, None, :], atol=1e-15)
    # and the vertex normals at an edge vertex are the 45-degree mean of the two faces
    N = vertex_normals(V, F)
    edge = np.flatnonzero((np.abs(V) > 1 - 1e-12).sum(axis=1) == 2)[0]
    assert np.isclose(np.abs(N[edge]).max(), np.sqrt(0.5), atol=1e-12)


def test_a_smooth_mesh_has_no_crease_at_sixty_degrees():
    V, F = icosphere(3)                         # neighbouring faces turn by about 4 degrees
    assert np.allclose(corner_normals(V, F, CREASE_ANGLE), vertex_normals(V, F)[F],
                       atol=1e-15)


def test_a_jack_creases_its_convex_and_concave_edges_alike():
    V, F = jack(2)
    Nc = corner_normals(V, F, 60.0)
    assert np.allclose(Nc, face_normals(V, F)[:, None, :], atol=1e-15)


@pytest.mark.parametrize("angle", [0.0, -5.0, 180.5, float("nan")])
def test_bad_crease_angles_are_refused(angle):
    V, F = cube(1)
    with pytest.raises(ValueError, match=r"crease_angle must be in \(0, 180\]"):
        corner_normals(V, F, angle)


def test_correspondence_with_creases_is_the_flat_cube_with_its_face_normals():
    V, F = cube(4)
    Vs = V / np.linalg.norm(V, axis=1, keepdims=True)        # radial: fold-free on a cube
    C = Correspondence(V, F, Vs, crease_angle=60.0)
    face, beta = C.sample_barycentric(3000, rng=0)
    q, n = C.to_mesh(face, beta)
    assert np.allclose(n, face_normals(V, F)[face], atol=1e-12)
    assert np.allclose(C.phong_point(face, beta), q, atol=1e-12)   # no bulge off the faces
    # without creases the Phong points leave the faces along the edges
    smooth = Correspondence(V, F, Vs)
    assert np.abs(smooth.phong_point(face, beta) - q).max() > 1e-2
    # a vertex's own target normal is one of its faces' normals
    Nf = face_normals(V, F)
    for v in (0, 5, 17):
        faces = np.flatnonzero((F == v).any(axis=1))
        assert np.isclose(np.max(Nf[faces] @ C.N_target[v]), 1.0)


def test_phong_gap_is_the_chordal_error_on_smooth_meshes_and_grows_at_coarse_edges():
    # on icospheres the gap falls with the square of the edge length (a quarter per level)
    g = [phong_gap(*icosphere(level)) for level in (2, 3, 4)]
    assert 3.5 < g[0] / g[1] < 4.5 and 3.5 < g[1] / g[2] < 4.5
    # a cube's gap is all in the strips of triangles along its edges: their offset and their
    # share of the area both fall with the edge length
    c = [phong_gap(*cube(n)) for n in (4, 8, 16)]
    assert 3.5 < c[0] / c[1] < 4.5 and 3.5 < c[1] / c[2] < 4.5
    # the "auto" rule: the coarse jack creases, the fine one does not
    assert phong_gap(*jack(6)) > CREASE_GAP > phong_gap(*jack(16))


def test_normal_turn_is_the_median_edge_arc_on_a_sphere():
    # an icosphere's vertex normals are nearly its (unit) vertices (level 0 exactly: every
    # vertex alike): across an edge they turn by about the edge's arc, so the measure is
    # about the median arc, halving with each level
    from sns_np.mesh._arrays import unique_edges
    for level, rel in ((0, 1e-9), (1, 0.02), (3, 0.02)):
        V, F = icosphere(level)
        E = unique_edges(F, len(V))[0]
        arcs = np.degrees(np.arccos(np.einsum("ij,ij->i", V[E[:, 0]], V[E[:, 1]])))
        assert normal_turn(V, F) == pytest.approx(np.median(arcs), rel=rel)
    t = [normal_turn(*icosphere(level)) for level in (2, 3, 4)]
    assert 1.9 < t[0] / t[1] < 2.1 and 1.9 < t[1] / t[2] < 2.1


def test_coarseness_for_the_size_or_for_the_curvature():
    # BOBBLE's ripples at icosphere level 5: fine for its size (the Phong gap), coarse for its
    # curvature (its normals turn by about 31 degrees per edge); the ellipsoid at the same
    # level is fine by both; at level 2 it is coarse for its size
    V, F = Bobble().mesh(5)
    gap, turn = phong_gap(V, F), normal_turn(V, F)
    assert gap < CREASE_GAP and turn > COARSE_TURN
    coarse, why = coarseness(gap, turn)
    assert coarse and why.startswith("a coarse mesh") and f"{turn:.1f} deg" in why
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(5)
    assert coarseness(phong_gap(V, F), normal_turn(V, F))[0] is False
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    gap, turn = phong_gap(V, F), normal_turn(V, F)
    assert gap > CREASE_GAP and turn < COARSE_TURN and coarseness(gap, turn)[0]


def _tiny(V, F, **kw):
    return fit_mesh(V, F, width=8, depth=1, steps=2, batch=64, n_eval=50, progress=False,
                    **kw)


def test_fit_mesh_records_the_crease_choice():
    S, report = _tiny(*jack(6))
    assert S.metadata["crease_angle"] == CREASE_ANGLE == report.choices["creases"]["value"]
    assert "coarse mesh" in report.choices["creases"]["why"]
    S, report = _tiny(*icosphere(2), creases=30)
    assert S.metadata["crease_angle"] == 30.0 and report.choices["creases"]["why"] == "given"
    S, report = _tiny(*jack(6), creases="none")
    assert S.metadata["crease_angle"] is None


@pytest.mark.parametrize("bad", ["sharp", 0, 200, True, None, "60"])
def test_fit_mesh_refuses_bad_creases_before_the_embedding(bad, monkeypatch):
    import sns_np.mesh as mesh

    def no_embedding(*a, **k):
        raise AssertionError("the embedding ran")

    monkeypatch.setattr(mesh, "spherical_embedding", no_embedding)
    with pytest.raises(ValueError, match="creases must be 'auto', 'none' or an angle"):
        _tiny(*jack(2), creases=bad)


def test_a_checkpoint_knows_the_targets_it_was_made_with():
    from sns_np.surface._targets import _fingerprint, _MeshTarget
    V, F = cube(2)
    Vs = V / np.linalg.norm(V, axis=1, keepdims=True)
    plain = _MeshTarget(V, F, Vs, verbose=False)
    creased = _MeshTarget(V, F, Vs, verbose=False, crease_angle=60.0)
    flat = _MeshTarget(V, F, Vs, verbose=False, smooth="none")
    assert plain.fingerprint == _fingerprint(V, F)          # the checkpoints made before
    assert len({plain.fingerprint, creased.fingerprint, flat.fingerprint}) == 3
