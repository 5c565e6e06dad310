"""Sampling weighted by the error: the weighted loss and its cotangents, the sampler's draw
and weights (the same objective as the uniform draw), and the fit that uses it."""

import numpy as np
import pytest

from sns_np.errors import ModelFileError
from sns_np.options import AUTO, CLOSEST_NORMAL_AREA, CLOSEST_NORMAL_MAX, COARSE_CLOSEST_NORMAL
from sns_np.shapes import Bobble, Ellipsoid
from sns_np.surface import fit_mesh, fit_shape, position_normal_loss
from sns_np.surface._adaptive import ErrorSampler, face_cells
from sns_np.surface._targets import _MeshTarget
from sns_np.testing import check_gradient

TINY = dict(width=12, depth=1, batch=256, n_eval=500, progress=False, lr=1e-3,
            input_scale=4.0)


@pytest.fixture(scope="module")
def target():
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    return _MeshTarget(V, F, verbose=False)


def test_weighted_loss_cotangents_by_differences():
    g = np.random.default_rng(3)
    y, JD = g.standard_normal((7, 3)), g.standard_normal((7, 3, 2))
    q, nt = g.standard_normal((7, 3)), g.standard_normal((7, 3))
    nt /= np.linalg.norm(nt, axis=1, keepdims=True)
    w = g.uniform(0.2, 3.0, 7)
    for tw in (1.0, 0.3):
        def fun(theta):                    # loss and cotangents of y and JD, flattened
            val, dy, dJD, _ = position_normal_loss(
                theta[:21].reshape(7, 3), theta[21:].reshape(7, 3, 2), q, nt, 7, 0.4,
                tangent_weight=tw, sample_weight=w)
            return val, np.concatenate([dy.ravel(), dJD.ravel()])

        assert check_gradient(fun, np.concatenate([y.ravel(), JD.ravel()])) < 1e-7
        val, dy, dJD, parts = position_normal_loss(y, JD, q, nt, 7, 0.4, tangent_weight=tw,
                                                   sample_weight=w, pointwise=True)
        # the weighted loss is the weighted mean of the unweighted per-point errors
        assert np.isclose(val, (w * parts["pointwise"]).sum() / 7)
        plain = position_normal_loss(y, JD, q, nt, 7, 0.4, tangent_weight=tw)[0]
        assert np.isclose(plain, parts["pointwise"].sum() / 7)
        assert not np.isclose(val, plain)


def test_unit_weights_are_the_plain_loss():
    g = np.random.default_rng(4)
    y, JD = g.standard_normal((5, 3)), g.standard_normal((5, 3, 2))
    q, nt = g.standard_normal((5, 3)), np.tile([0.0, 0.0, 1.0], (5, 1))
    a = position_normal_loss(y, JD, q, nt, 5, 0.2)
    b = position_normal_loss(y, JD, q, nt, 5, 0.2, sample_weight=np.ones(5))
    assert np.isclose(a[0], b[0]) and np.allclose(a[1], b[1]) and np.allclose(a[2], b[2])


def test_face_cells_cover_every_face_with_compact_patches():
    from sns_np.mesh import face_areas, icosphere
    V, F = icosphere(4)
    c = V[F].mean(axis=1)
    labels = face_cells(c, face_areas(V, F), 200, seed=1)
    assert labels.shape == (len(F),) and set(np.unique(labels)) == set(range(200))
    # patches of neighbouring faces: small next to the sphere
    spread = max(np.linalg.norm(c[labels == k] - c[labels == k].mean(0), axis=1).max()
                 for k in range(200))
    assert spread < 0.35
    assert np.array_equal(face_cells(c, face_areas(V, F), len(F) + 1), np.arange(len(F)))


def test_sampler_follows_the_error_and_keeps_the_objective(target):
    s = ErrorSampler(target, batch=64)          # few cells: 64 / 0.01 / 8 = 800 of 320 faces
    assert s.n_cells == len(target.face_area)
    g = np.random.default_rng(0)
    hot = target.face_centroid[:, 2] > 0.5      # pretend the error is all at the top
    for _ in range(40):
        p, q, n, w = s.sample(256, g)
        face = s.labels[s._cells]
        s.observe(np.where(hot[face], 1.0, 1e-4))
    frac_area = target.face_area[hot].sum() / target.face_area.sum()
    frac_prob = s.prob[s.labels[hot]].sum()
    assert frac_prob > 2 * frac_area            # drawn where the error is
    assert np.all(s.weight < 1.0 / (1.0 - s.mix) + 1e-12)
    # the weighted mean of any function is the area mean: the same objective
    p, q, n, w = s.sample(200_000, g)
    s.observe(np.zeros(len(p)))
    for fval in (lambda x: x[:, 2] ** 2, lambda x: np.exp(x[:, 0])):
        area_mean = fval(target.sample(400_000, np.random.default_rng(1))[1]).mean()
        assert abs((w * fval(q)).mean() - area_mean) < 0.01 * abs(area_mean) + 2e-3
        assert abs(fval(q).mean() - area_mean) > 3 * abs((w * fval(q)).mean() - area_mean)
    assert abs(w.mean() - 1.0) < 0.01
    # each point lies in the face the sampler says: the sphere point maps back to it
    assert np.allclose(target.evaluate_at(p[:100])[0], q[:100], atol=1e-9)


def test_sampler_state_round_trip_draws_the_same(target):
    a, b = ErrorSampler(target, batch=64), ErrorSampler(target, batch=64)
    g = np.random.default_rng(5)
    for _ in range(13):
        p, *_ = a.sample(128, g)
        a.observe(np.abs(p[:, 0]))
    b.load_state_dict(a.state_dict())
    ga, gb = np.random.default_rng(9), np.random.default_rng(9)
    assert all(np.array_equal(x, y) for x, y in zip(a.sample(50, ga), b.sample(50, gb)))
    with pytest.raises(ValueError, match="one error per sample"):
        a.observe(np.ones(3))
    for kw, name in ((dict(mix=1.0), "mix"), (dict(decay=1.0), "decay"), (dict(every=0), "every")):
        with pytest.raises(ValueError, match=name):
            ErrorSampler(target, batch=64, **kw)
    bad = dict(a.state_dict(), prob=np.ones(4))
    with pytest.raises(ValueError, match="cells"):
        b.load_state_dict(bad)


def test_stratified_draw_gives_each_cell_its_share_and_a_calmer_batch(target):
    g = np.random.default_rng(2)
    strat, iid = (ErrorSampler(target, batch=64, stratified=b) for b in (True, False))
    prob = target.face_area * g.uniform(0.2, 2.0, len(target.face_area))
    for s in (strat, iid):
        s._set_probabilities(prob / prob.sum())
    n = 1000
    # one point per slice of the cumulative probability: every stretch of the cells' curve,
    # and so every cell, gets its share n P(c) to within one point either side
    counts = {}
    for name, s in (("strat", strat), ("iid", iid)):
        s.sample(n, g)
        counts[name] = np.bincount(s._cells, minlength=s.n_cells)
        s.observe(np.zeros(n))
    assert np.abs(counts["strat"] - n * strat.prob).max() < 2.0
    assert np.abs(counts["iid"] - n * iid.prob).max() > 2.0
    # so a batch's weighted mean of a smooth function scatters much less about the area mean
    spread = {}
    for name, s in (("strat", strat), ("iid", iid)):
        means = []
        for _ in range(200):
            p, q, nrm, w = s.sample(256, g)
            s.observe(np.zeros(256))
            means.append((w * q[:, 2] ** 2).mean())
        spread[name] = np.std(means)
    assert spread["strat"] < 0.5 * spread["iid"]
    with pytest.raises(ValueError, match="stratified must be True or False"):
        ErrorSampler(target, batch=64, stratified="yes")


def test_morton_order_walks_through_neighbours():
    from sns_np.mesh import icosphere
    from sns_np.surface._adaptive import morton_order
    V, _ = icosphere(4)                 # 2,562 points, edges about 0.08 long
    o = morton_order(V)
    assert sorted(o.tolist()) == list(range(len(V)))
    # consecutive points along the curve are mostly neighbours; in a random order they are
    # a sphere's width apart
    step = np.median(np.linalg.norm(np.diff(V[o], axis=0), axis=1))
    scattered = np.median(np.linalg.norm(np.diff(V[np.random.default_rng(1).permutation(
        len(V))], axis=0), axis=1))
    assert step < 0.1 < 1.0 < scattered
    assert np.array_equal(morton_order(np.zeros((3, 3))), [0, 1, 2])   # a degenerate cube


@pytest.mark.slow_nojit
def test_fit_with_error_sampling_resumes_exactly(tmp_path):
    """With a quarter of each batch at the vertices: the draw on the faces and at the
    vertices, and the sampler's state, all continue exactly."""
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    opts = dict(steps=30, dtype="float64", sampling="error", vertex_fraction=0.25, **TINY)
    S_full, r_full = fit_mesh(V, F, **opts)
    assert r_full.options["sampling"] == "error" and np.isfinite(r_full.normal_mean_deg)
    ck = tmp_path / "ck.npz"

    def interrupt(step, info):
        if step == 20:                   # between two updates of the probabilities
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fit_mesh(V, F, checkpoint=ck, callback=interrupt, history_every=5, **opts)
    S_res, r = fit_mesh(V, F, checkpoint=ck, resume=True, **opts)
    assert r.steps == 30 and np.array_equal(S_res.net.pack(), S_full.net.pack())
    # a checkpoint drawn by area is not continued by an error-weighted fit
    with pytest.raises(ModelFileError, match="different fit"):
        fit_mesh(V, F, checkpoint=ck, resume=True, **dict(opts, sampling="area"))


def test_sampling_choice_and_refusals():
    V, F = Bobble().mesh(2)
    opts = dict(TINY, steps=2)
    _, r = fit_mesh(V, F, **opts)               # a detailed mesh: the detailed end's draw
    assert r.options["sampling"] == AUTO["detailed"]["sampling"]
    assert r.choices["sampling"]["why"].startswith("detailed")
    _, r = fit_mesh(*Ellipsoid(1.0, 1.3, 0.7).mesh(2), **opts)
    assert r.options["sampling"] == "area"      # smooth: uniform
    _, r = fit_shape(Bobble(), **opts)          # a detailed map: its parameter sphere's cells
    assert r.options["sampling"] == AUTO["detailed"]["sampling"] == "error"
    assert r.choices["sampling"]["why"].startswith("detailed")
    _, r = fit_shape(Ellipsoid(1.0, 1.3, 0.7), **opts)
    assert r.options["sampling"] == "area"
    # without the derivative losses the map's draw is a mesh's: points, targets, weights
    _, r = fit_shape(Bobble(), jacobian_weight=0, hessian_weight=0, **opts)
    assert r.options["sampling"] == "error" and r.steps == 2

    class Drawn:                                # a target that draws its points itself
        parametrisation, area, center, scale = "exact", 4 * np.pi, np.zeros(3), 1.0
        bbox_diagonal, fingerprint = 2 * np.sqrt(3), "drawn"

        def sample(self, n, rng):
            from sns_np.sampling import uniform_sphere
            p = uniform_sphere(n, rng)
            return p, p, p

        evaluate_at = staticmethod(lambda p: (p, p))

    from sns_np.surface import fit_sampler
    with pytest.raises(ValueError, match="cells to weight"):
        fit_sampler(Drawn(), sampling="error", **opts)
    with pytest.raises(ValueError, match="sampling"):
        fit_mesh(V, F, sampling="stratified", **opts)


def test_vertex_samples_are_the_face_targets_at_the_corners(target):
    """A vertex drawn by sample_vertices is the face target at a one-hot barycentric corner:
    the same sphere point, the vertex itself (the Phong point at a corner) and its normal."""
    p, q, n = target.sample_vertices(40, np.random.default_rng(1))
    F = target.corr.F
    i = np.argmin(np.linalg.norm(target.corr.Vs[None] - p[:, None], axis=2), axis=1)
    face = np.argmax((F[None] == i[:, None, None]).any(axis=2), axis=1)
    beta = (F[face] == i[:, None]).astype(float)
    pf, qf, nf = target._points(face, beta)
    assert np.allclose(p, pf, atol=1e-12) and np.allclose(q, qf, atol=1e-12)
    assert np.allclose(n, nf, atol=1e-12)
    assert np.allclose(q * target.scale + target.center, target.corr.V[i], atol=1e-12)


def test_a_fit_draws_its_share_of_vertices(monkeypatch):
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
    drawn = []
    original = _MeshTarget.sample_vertices

    def record(self, n, rng):
        drawn.append(n)
        return original(self, n, rng)

    monkeypatch.setattr(_MeshTarget, "sample_vertices", record)
    for sampling in ("area", "error"):
        drawn.clear()
        _, r = fit_mesh(V, F, steps=3, sampling=sampling, vertex_fraction=0.3, **TINY)
        assert drawn == [77] * 3 and r.options["vertex_fraction"] == 0.3   # 0.3 x 256
    drawn.clear()
    fit_mesh(V, F, steps=2, sampling="error", vertex_fraction=1.0, **TINY)
    assert drawn == [256] * 2                                # no face samples at all
    # the default: a quarter of the batch at the vertices of a coarse mesh (level 2: its
    # Phong tessellation stands more than CREASE_GAP off its triangles), none on a finer one
    # (level 4: its gap below CREASE_GAP, its normals turning by 4-5 deg per edge)
    drawn.clear()
    _, r = fit_mesh(V, F, steps=2, **TINY)
    assert drawn == [64] * 2 and r.choices["vertex_fraction"]["value"] == 0.25
    assert "a coarse mesh" in r.choices["vertex_fraction"]["why"]
    # and its nearest-point phase leans on positions: its interpolated normals are guesses
    assert r.options["closest_normal_weight"] == COARSE_CLOSEST_NORMAL
    drawn.clear()
    _, r = fit_mesh(*Ellipsoid(1.0, 1.3, 0.7).mesh(4), steps=2, **TINY)
    assert drawn == [] and r.options["vertex_fraction"] == 0.0
    assert "a fine mesh" in r.choices["vertex_fraction"]["why"]
    assert r.options["closest_normal_weight"] == min(CLOSEST_NORMAL_MAX, CLOSEST_NORMAL_AREA * 4
                                                     * np.pi / 5120)    # level 4: 5,120 faces


def test_vertex_fraction_refusals():
    with pytest.raises(ValueError, match="vertex_fraction=0.5 needs a mesh target"):
        fit_shape(Bobble(), steps=2, vertex_fraction=0.5, **TINY)
    with pytest.raises(ValueError, match=r"vertex_fraction must lie in \[0, 1\], got 1.5"):
        fit_mesh(*Ellipsoid(1.0, 1.3, 0.7).mesh(1), steps=2, vertex_fraction=1.5, **TINY)


def test_uniform_in_spherical_triangles_is_uniform_by_area():
    """Counts in the four midpoint sub-triangles of a large and of a skewed triangle follow
    their areas (chi-square, 3 degrees of freedom), and every point lies inside."""
    from sns_np.mesh import spherical_triangle_areas, uniform_in_spherical_triangles

    def unit(x):
        return np.asarray(x, float) / np.linalg.norm(x)

    def inside(P, a, b, c):
        return np.logical_and.reduce([(P @ np.cross(x, y)) * np.dot(z, np.cross(x, y))
                                      >= -1e-12 for x, y, z in ((a, b, c), (b, c, a),
                                                                (c, a, b))])

    for tri in ((np.eye(3)[0], np.eye(3)[1], np.eye(3)[2]),
                (unit([1, 0, 0]), unit([0, 1, 0.05]), unit([0.5, 0.6, 0.9]))):
        n = 200_000
        P = uniform_in_spherical_triangles(*(np.tile(x, (n, 1)) for x in tri),
                                           np.random.default_rng(1))
        assert np.allclose(np.linalg.norm(P, axis=1), 1.0)
        A, B, C = tri
        assert np.all(inside(P, A, B, C))
        Vs = np.array([A, B, C, unit(A + B), unit(B + C), unit(C + A)])
        F = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])
        area = spherical_triangle_areas(Vs, F)
        counts = np.array([inside(P, *Vs[f]).sum() for f in F])
        expected = n * area / area.sum()
        assert ((counts - expected) ** 2 / expected).sum() < 16.3      # p = 0.001
        # and the plain normalised flat-barycentric draw is not uniform: the test can fail
        if tri[0][0] == 1 and tri[1][1] == 1 and tri[2][2] == 1:
            r = np.random.default_rng(2).dirichlet(np.ones(3), n) @ np.array(tri)
            r /= np.linalg.norm(r, axis=1, keepdims=True)
            flat = np.array([inside(r, *Vs[f]).sum() for f in F])
            assert ((flat - expected) ** 2 / expected).sum() > 100


def test_shape_cells_draw_the_uniform_objective():
    """An analytic map's cells tile the sphere; a draw of cells by area and points within
    them is uniform on the sphere; the sampler's weighted means are the sphere means."""
    from sns_np.surface._targets import _ShapeTarget
    t = _ShapeTarget(Bobble())
    assert np.isclose(t.face_area.sum(), 4 * np.pi)
    s = ErrorSampler(t, batch=512)
    g = np.random.default_rng(0)
    hot = t.face_centroid[:, 0] > 0.6
    for _ in range(30):
        p, q, n, JT, ST, w = s.sample(512, g, jets=True)
        assert JT.shape == (512, 3, 2) and ST is None
        s.observe(np.where(hot[s.labels[s._cells]], 1.0, 1e-4))
    assert s.prob[s.labels[hot]].sum() > 2 * t.face_area[hot].sum() / (4 * np.pi)
    p, q, n, w = s.sample(200_000, g)                 # without jets: as a mesh's draw
    s.observe(np.zeros(len(p)))
    # sphere means (x uniform in [-1, 1] by Archimedes): x^2 -> 1/3, exp(x) -> sinh(1)
    for fval, exact in ((lambda x: x[:, 0] ** 2, 1.0 / 3.0),
                        (lambda x: np.exp(x[:, 0]), np.sinh(1.0))):
        assert abs((w * fval(p)).mean() - exact) < 0.01 * exact
        assert abs(fval(p).mean() - exact) > 3 * abs((w * fval(p)).mean() - exact)
    # the jets are the map's own at the drawn points
    q2, n2 = t.evaluate_at(p[:50])
    assert np.allclose(q[:50], q2, atol=1e-12) and np.allclose(n[:50], n2, atol=1e-12)


def test_weighted_derivative_losses_by_differences():
    from sns_np.surface.losses import hessian_loss, jacobian_loss
    g = np.random.default_rng(7)
    JD, JT = g.standard_normal((5, 3, 2)), g.standard_normal((5, 3, 2))
    D2D, Jp, T2 = (g.standard_normal((5, 3, 2, 2)), g.standard_normal((5, 3)),
                   g.standard_normal((5, 3, 2, 2)))
    w = g.uniform(0.2, 3.0, 5)

    def fj(x):
        v, d, _ = jacobian_loss(x.reshape(5, 3, 2), JT, 5, 0.7, sample_weight=w)
        return v, d.ravel()

    def fh(x):
        v, dD, dJ, _ = hessian_loss(x[:60].reshape(5, 3, 2, 2), x[60:].reshape(5, 3), T2, 5,
                                    0.3, sample_weight=w)
        return v, np.concatenate([dD.ravel(), dJ.ravel()])

    assert check_gradient(fj, JD.ravel()) < 1e-7
    assert check_gradient(fh, np.concatenate([D2D.ravel(), Jp.ravel()])) < 1e-7
    # unit weights are the plain losses; other weights are not
    assert np.isclose(jacobian_loss(JD, JT, 5, 0.7, sample_weight=np.ones(5))[0],
                      jacobian_loss(JD, JT, 5, 0.7)[0])
    assert np.isclose(hessian_loss(D2D, Jp, T2, 5, 0.3, sample_weight=np.ones(5))[0],
                      hessian_loss(D2D, Jp, T2, 5, 0.3)[0])
    assert not np.isclose(fj(JD.ravel())[0], jacobian_loss(JD, JT, 5, 0.7)[0])
