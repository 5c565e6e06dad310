"""The fine sample of a smooth surface: the curvature jitter that recognises one, the rule
(``smooth_sampling``) and the positions-only choices a fit makes for it."""

import numpy as np
import pytest

from sns_np.mesh import curvature_jitter, icosphere
from sns_np.options import (
    SAMPLE_JITTER,
    SAMPLE_TANGENT_WEIGHT,
    SAMPLE_VERTEX_FRACTION,
)
from sns_np.shapes import Bobble, Ellipsoid, PerturbedEllipsoid, Spike
from sns_np.surface import fit_mesh
from sns_np.surface._targets import smooth_sampling


def _noisy(V, amplitude, seed=0):
    """Each vertex moved along its radius by ``amplitude`` times a standard normal."""
    return V * (1 + amplitude * np.random.default_rng(seed).standard_normal(len(V)))[:, None]


def test_curvature_jitter_vanishes_on_the_sphere_and_grows_with_noise_at_the_vertices():
    V, F = icosphere(3)
    assert curvature_jitter(V, F) < 1e-4                # H nearly the same at every vertex
    values = [curvature_jitter(_noisy(V, a), F) for a in (1e-3, 3e-3, 1e-2)]
    assert 0.05 < values[0] < values[1] < values[2]     # rough at the vertex spacing
    assert values[2] > 5 * SAMPLE_JITTER


def test_curvature_jitter_is_invariant_to_scale_and_rigid_motion():
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(3)
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    j = curvature_jitter(V, F)
    assert curvature_jitter(2.5 * V @ R.T + [1.0, -2.0, 0.5], F) == pytest.approx(j, rel=1e-9)
    # a mesh's vertex order is not its geometry
    perm = np.random.default_rng(1).permutation(len(V))
    inverse = np.argsort(perm)
    assert curvature_jitter(V[perm], inverse[F]) == pytest.approx(j, rel=1e-9)


def test_curvature_jitter_falls_as_a_smooth_surface_is_sampled_finer():
    shape = Ellipsoid(1.0, 1.3, 0.7)
    values = [curvature_jitter(*shape.mesh(level)) for level in (2, 3, 4)]
    assert values[0] > values[1] > values[2] and values[2] < 0.01


def test_the_paper_meshes_and_a_cad_part_by_the_rule():
    # SPIKE at level 5 is a fine sample (its normals turn by 10 degrees per edge, its
    # curvature varies slowly); BOBBLE's ripples at the same level are coarse for their
    # curvature alone (its normals turn by 31 degrees per edge, its Phong points stay near
    # its triangles): rippled; a cube's curvature lives on its edges' vertices alone
    from sns_np.mesh import normal_turn
    from sns_np.surface._targets import phong_gap

    def rule(V, F):
        return smooth_sampling(phong_gap(V, F), normal_turn(V, F), curvature_jitter(V, F))

    V, F = Spike().mesh(5)
    kind, why = rule(V, F)
    assert kind == "fine" and curvature_jitter(V, F) < SAMPLE_JITTER / 2
    assert why.startswith("a fine sample of a smooth surface")
    kind, why = rule(*Bobble().mesh(5))
    assert kind == "rippled" and "coarse for its curvature alone" in why
    from .test_creases import cube
    V, F = cube(12)
    assert rule(V, F)[0] is None and curvature_jitter(V, F) > 5 * SAMPLE_JITTER


def test_smooth_sampling_names_its_measures_and_thresholds():
    from sns_np.options import COARSE_TURN, CREASE_GAP
    kind, why = smooth_sampling(3e-4, 10.0, 0.0712)
    assert kind == "fine" and "0.071" in why and f"<= {SAMPLE_JITTER:g}" in why
    kind, why = smooth_sampling(3e-4, 10.0, SAMPLE_JITTER * 1.01)
    assert kind is None and why.startswith("detail at its vertex spacing")
    assert smooth_sampling(3e-4, 10.0, SAMPLE_JITTER)[0] == "fine"   # the threshold itself
    # coarse for its size: never, whatever its jitter; for its curvature alone: rippled
    kind, why = smooth_sampling(2 * CREASE_GAP, 10.0, 0.0)
    assert kind is None and why.startswith("a coarse mesh") and "not a fine sample" in why
    assert smooth_sampling(2 * CREASE_GAP, 2 * COARSE_TURN, 0.0)[0] is None
    kind, why = smooth_sampling(CREASE_GAP, COARSE_TURN + 1, 0.9)
    assert kind == "rippled" and "31.1" not in why and f"{COARSE_TURN + 1:.1f} deg" in why
    assert smooth_sampling(CREASE_GAP, COARSE_TURN, 0.9)[0] is None   # not beyond the turn


def _tiny(V, F, **kw):
    return fit_mesh(V, F, width=8, depth=1, steps=2, batch=64, n_eval=50, progress=False,
                    **kw)


@pytest.fixture(scope="module")
def sample_mesh():
    """A rippled ellipsoid at icosphere level 4: fine, curvature jitter 0.10, and detailed by
    the read-out (0.74 of the way to the detailed end)."""
    from sns_np.mesh import spherical_embedding
    V, F = PerturbedEllipsoid(amplitude=0.13, frequency=5.5).mesh(4)
    return V, F, spherical_embedding(V, F, verbose=False)[0]


def _tiny_on(mesh, V=None, **kw):
    """A two-step fit of ``mesh`` (vertices, faces, embedding), its vertices replaced by
    ``V`` if given (the same connectivity: the embedding still serves)."""
    V0, F, Vs = mesh
    return _tiny(V0 if V is None else V, F, Vs=Vs, **kw)


def test_a_fine_sample_is_fitted_by_its_positions_and_says_so(sample_mesh):
    S, report = _tiny_on(sample_mesh)
    c = report.choices
    assert c["smooth_sample"]["value"] == "fine"
    assert c["smooth_sample"]["why"].startswith("a fine sample of a smooth surface")
    assert c["normal_weight"]["value"] == 0.0
    assert c["vertex_fraction"]["value"] == SAMPLE_VERTEX_FRACTION
    assert c["tangent_weight"]["value"] == SAMPLE_TANGENT_WEIGHT
    assert c["closest_after"]["value"] == 1.0
    assert c["closest_normal_weight"]["value"] == 0.0 and c["area_weight_max"]["value"] == 0.0
    assert S.metadata["fit"]["choices"]["smooth_sample"]["value"] == "fine"
    assert "at most" not in c["input_scale"]["why"]   # a fine sample keeps the detail's scale


def test_a_given_normal_weight_keeps_the_normal_following_defaults(sample_mesh):
    _, report = _tiny_on(sample_mesh, normal_weight=1.0)
    c = report.choices
    assert "smooth_sample" not in c and "normal_weight" not in c
    assert c["tangent_weight"]["value"] == 1.0 and c["vertex_fraction"]["value"] == 0.0


def test_a_given_choice_stands_inside_the_rule(sample_mesh):
    _, report = _tiny_on(sample_mesh, tangent_weight=0.3, vertex_fraction=0.1)
    c = report.choices
    assert c["smooth_sample"]["value"] == "fine" and c["normal_weight"]["value"] == 0.0
    assert "tangent_weight" not in c and "vertex_fraction" not in c
    assert report.options["tangent_weight"] == 0.3 and report.options["vertex_fraction"] == 0.1


def test_a_rough_mesh_and_the_normals_target_are_not_samples(sample_mesh):
    _, report = _tiny_on(sample_mesh, _noisy(sample_mesh[0], 3e-3))
    c = report.choices
    assert c["smooth_sample"]["value"] is False
    assert c["smooth_sample"]["why"].startswith("detail at its vertex spacing")
    assert c["tangent_weight"]["value"] == 1.0 and "normal_weight" in report.options
    assert report.options["normal_weight"] > 0
    _, report = _tiny_on(sample_mesh, smooth="normals")
    assert report.choices["smooth_sample"]["value"] is False
    assert "'normals' target" in report.choices["smooth_sample"]["why"]


def test_a_smooth_target_keeps_its_normals():
    # the demo's ellipsoid is a fine sample too (jitter 0.004), but a smooth target: fitted at
    # scale 4 in a short budget, where following its normals is faster
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(4)
    _, report = _tiny(V, F)
    c = report.choices
    assert c["smooth_sample"]["value"] is False
    assert c["smooth_sample"]["why"].startswith("a fine sample of a smooth surface")
    assert "but a smooth target" in c["smooth_sample"]["why"]
    assert c["tangent_weight"]["value"] == 1.0 and report.options["normal_weight"] > 0
    assert report.options["vertex_fraction"] == 0.0


def test_a_warm_start_keeps_its_loss(sample_mesh):
    S, _ = _tiny_on(sample_mesh, normal_weight=1.0)
    _, report = _tiny_on(sample_mesh, net=S.net)
    assert "smooth_sample" not in report.choices
    assert report.options["tangent_weight"] == 1.0


def test_a_rippled_mesh_is_fitted_by_its_positions_uncreased_at_a_capped_scale():
    # BOBBLE at level 5 (a rippled mesh needs many vertices: curvature times the edge large,
    # times its square small), coarse for its curvature alone: "auto" would crease it at 60
    # degrees and follow its normals; taken by its positions, it is left uncreased and its
    # first layer's scale is capped
    from sns_np.mesh import spherical_embedding
    from sns_np.options import CREASE_ANGLE, RIPPLED_INPUT_SCALE
    V, F = Bobble().mesh(5)
    Vs = spherical_embedding(V, F)[0]
    S, report = _tiny(V, F, Vs=Vs)
    c = report.choices
    assert c["smooth_sample"]["value"] == "rippled"
    assert c["creases"]["value"] is None and "no normals to crease" in c["creases"]["why"]
    assert S.metadata["crease_angle"] is None
    assert c["normal_weight"]["value"] == 0.0 and c["tangent_weight"]["value"] == 0.01
    assert c["input_scale"]["value"] == RIPPLED_INPUT_SCALE
    assert f"at most {RIPPLED_INPUT_SCALE:g} for ripples" in c["input_scale"]["why"]
    # with a normal weight given the rule is off: the coarse mesh's creases and scale
    S, report = _tiny(V, F, Vs=Vs, normal_weight=1.0)
    assert report.choices["creases"]["value"] == CREASE_ANGLE == S.metadata["crease_angle"]
    assert report.options["input_scale"] > RIPPLED_INPUT_SCALE
