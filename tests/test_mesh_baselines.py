import numpy as np
import pytest

from sns_np.mesh import baseline_curvatures, discrete_curvatures, icosphere, load

from .test_mesh_helpers import ellipsoid


def test_discrete_curvatures_on_spheres():
    V, F = icosphere(4)
    for r in (1.0, 2.5):
        c = discrete_curvatures(r * V, F)
        assert abs(c.H - 1 / r).max() < 0.01 / r
        assert abs(c.K - 1 / r ** 2).max() < 0.05 / r ** 2
        assert c.kmin is None


def test_discrete_gauss_bonnet_is_exact():
    V, F = ellipsoid(3)
    from sns_np.mesh import mass_matrix

    c = discrete_curvatures(V, F)
    assert (c.K * mass_matrix(V, F, "voronoi").diagonal()).sum() == pytest.approx(4 * np.pi)


def test_inward_orientation_flips_the_sign():
    V, F = icosphere(3)
    assert (discrete_curvatures(V, F[:, ::-1]).H < 0).all()


def test_libigl_baseline_on_spheres_follows_our_conventions():
    pytest.importorskip("igl")
    V, F = icosphere(4)
    for r in (1.0, 0.5):
        c = baseline_curvatures(r * V, F)
        assert abs(c.kmin - 1 / r).max() < 0.05 / r and abs(c.kmax - 1 / r).max() < 0.05 / r
        assert (c.kmin <= c.kmax).all()
        np.testing.assert_allclose(c.H, (c.kmin + c.kmax) / 2)
        np.testing.assert_allclose(c.K, c.kmin * c.kmax)
        assert np.allclose(np.linalg.norm(c.dmin, axis=1), 1)
        assert abs(np.einsum("ij,ij->i", c.dmin, V)).max() < 1e-2     # tangent


def test_libigl_baseline_on_an_ellipsoid_pole():
    pytest.importorskip("igl")
    V, F = ellipsoid(5, (1.0, 1.0, 3.0))
    c = baseline_curvatures(V, F)
    top = int(np.argmax(V[:, 2]))
    # at (0, 0, 3): both principal curvatures c / a^2 = 3
    assert c.kmin[top] == pytest.approx(3.0, rel=0.05)
    assert c.kmax[top] == pytest.approx(3.0, rel=0.05)
    eq = int(np.argmax(V[:, 0]))
    # at (1, 0, 0): curvatures a / c^2 = 1/9 (meridian) and 1/a = 1 (equator)
    assert c.kmin[eq] == pytest.approx(1 / 9, abs=0.03)
    assert c.kmax[eq] == pytest.approx(1.0, rel=0.05)


@pytest.mark.data
def test_uv_sphere_baselines(mesh_dir):
    pytest.importorskip("igl")
    V, F = load(mesh_dir / "uv_sphere.obj")                  # radius 0.7
    # the quadric fit is biased on this anisotropic mesh for large neighbourhoods
    c = baseline_curvatures(V, F, radius=2)
    assert np.median(np.abs(c.H - 1 / 0.7)) < 0.06
    d = discrete_curvatures(V, F)
    assert np.median(np.abs(d.H - 1 / 0.7)) < 0.05
