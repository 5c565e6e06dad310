import numpy as np
import pytest

from sns_np.errors import ShapeError
from sns_np.mesh import (
    Correspondence,
    EmbeddingError,
    SphereLocator,
    face_areas,
    icosphere,
    load,
    sample_surface,
    spherical_embedding,
    uniform_barycentric,
)

from .test_mesh_helpers import ellipsoid


def _corr(level=3, axes=(1.0, 1.5, 2.5)):
    Vs, F = icosphere(level)
    return Correspondence(Vs * np.asarray(axes), F, Vs)


def test_uniform_barycentric():
    b = uniform_barycentric(200000, rng=3)
    assert (b >= 0).all() and np.allclose(b.sum(axis=1), 1)
    # uniform on the triangle: each coordinate has mean 1/3 and P(b0 > 1/2) = 1/4
    assert np.allclose(b.mean(axis=0), 1 / 3, atol=3e-3)
    assert (b[:, 0] > 0.5).mean() == pytest.approx(0.25, abs=4e-3)


def test_faces_are_drawn_proportionally_to_area_not_area_squared():
    # two triangles of areas 1 and 3
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 1], [3, 0, 1], [0, 2, 1.0]])
    F = np.array([[0, 1, 2], [3, 4, 5]])
    A = face_areas(V, F)
    face, _ = sample_surface(V, F, 400000, rng=0)
    freq = np.bincount(face, minlength=2) / face.size
    np.testing.assert_allclose(freq, A / A.sum(), atol=3e-3)
    assert not np.allclose(freq, A ** 2 / (A ** 2).sum(), atol=0.05)


def test_samples_are_uniform_on_the_surface():
    # on an ellipsoid, the fraction of points with z > 0 is 1/2 and the mean is the centroid
    C = _corr(4)
    p, q, nrm = C.sample(200000, rng=1)
    assert abs(q.mean(axis=0)).max() < 0.01


def test_sample_shapes_units_and_reproducibility():
    C = _corr()
    p, q, nrm = C.sample(2048, rng=7)
    assert p.shape == q.shape == nrm.shape == (2048, 3)
    assert abs(np.linalg.norm(p, axis=1) - 1).max() < 1e-15            # on the sphere
    assert abs(np.linalg.norm(nrm, axis=1) - 1).max() < 1e-14
    p2, q2, n2 = C.sample(2048, rng=7)
    np.testing.assert_array_equal(q, q2)
    g = np.random.default_rng(5)
    assert not np.array_equal(C.sample(10, g)[0], C.sample(10, g)[0])


def test_sphere_to_mesh_correspondence_of_an_ellipsoid():
    # sphere vertices scaled by the axes; mesh points lie on the chord triangles, so they are
    # slightly inside the ellipsoid, and their normals are close to the ellipsoid normals
    axes = np.array([1.0, 1.5, 2.5])
    C = _corr(4, axes)
    p, q, nrm = C.sample(5000, rng=2)
    rho = np.sqrt(((q / axes) ** 2).sum(axis=1))
    assert 0.99 < rho.min() and rho.max() <= 1 + 1e-12
    n_true = q / axes ** 2
    n_true /= np.linalg.norm(n_true, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip((n_true * nrm).sum(1), -1, 1))).max() < 2.0
    # sphere point and mesh point come from the same barycentric point
    q_from_p = p * axes                                              # exact for a vertex only
    assert np.linalg.norm(q - q_from_p, axis=1).max() < 0.02


def test_round_trip_sample_locate():
    V, F = ellipsoid(3)
    Vs, _ = spherical_embedding(V, F, grid_level=3)
    C = Correspondence(V, F, Vs)
    g = np.random.default_rng(0)
    face, beta = sample_surface(V, F, 20000, rng=g)
    p = C.to_sphere(face, beta)
    f2, b2 = C.locate(p)
    inner = beta.min(axis=1) > 1e-9                  # points on an edge may switch faces
    assert (f2[inner] == face[inner]).all()
    assert abs(b2[inner] - beta[inner]).max() < 1e-9
    q, _ = C.to_mesh(face, beta)
    q2, _ = C.mesh_point(p)
    assert abs(q2 - q).max() < 1e-9


def test_vertices_map_to_vertices_and_random_points_are_all_located():
    C = _corr(3)
    q, nrm = C.mesh_point(C.Vs)
    np.testing.assert_allclose(q, C.V, atol=1e-12)
    np.testing.assert_allclose(nrm, C.N, atol=1e-12)
    p = np.random.default_rng(4).standard_normal((100000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    face, beta = C.locate(p)
    assert (beta >= 0).all() and np.allclose(beta.sum(1), 1)
    back = C.to_sphere(face, beta)
    assert abs(back - p).max() < 1e-12


def test_locator_on_a_distorted_embedding_uses_the_fallbacks():
    # squash the sphere's vertices towards one pole by a Möbius-like map: large and tiny
    # triangles; the centroid search then often needs more candidates
    V, F = icosphere(4)
    P = V + [0, 0, 0.9]
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    loc = SphereLocator(P, F)
    p = np.random.default_rng(1).standard_normal((20000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    face, beta = loc.locate(p, k=1)
    recon = (beta[:, :, None] * P[F[face]]).sum(axis=1)
    recon /= np.linalg.norm(recon, axis=1, keepdims=True)
    assert abs(recon - p).max() < 1e-12


def test_bad_input():
    V, F = icosphere(2)
    with pytest.raises(EmbeddingError, match="folds"):
        Correspondence(V, F, V * [1, 1, -1])
    with pytest.raises(ShapeError, match="unit vectors"):
        Correspondence(V, F, 2 * V)
    with pytest.raises(ShapeError, match="shape of V"):
        Correspondence(V, F, V[:-1])
    with pytest.raises(ShapeError, match="unit sphere"):
        Correspondence(V, F, V).locate(2 * V[:3])


@pytest.mark.data
def test_round_trip_on_a_shared_mesh(mesh_dir):
    V, F = load(mesh_dir / "spot_triangulated.obj")
    Vs, _ = spherical_embedding(V, F)
    C = Correspondence(V, F, Vs)
    p, q, _ = C.sample(20000, rng=9)
    q2, _ = C.mesh_point(p)
    assert np.linalg.norm(q2 - q, axis=1).max() < 1e-9 * np.ptp(V)
