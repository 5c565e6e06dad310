import numpy as np
import pytest

from sns_np.mesh import eigenvalues, icosphere, laplacian_eigenmodes, load, mass_matrix

SPHERE = np.array([2.0] * 3 + [6.0] * 5 + [12.0] * 7)   # l(l+1), multiplicity 2l+1


@pytest.mark.parametrize("mass", ["full", "lumped"])
def test_unit_sphere_converges_to_l_l_plus_1(mass):
    errs = []
    for level in (1, 2, 3, 4):
        V, F = icosphere(level)
        lam = eigenvalues(V, F, 15, mass=mass)
        errs.append(np.abs(lam - SPHERE).max())
        assert np.all(np.diff(lam) >= 0) and lam[0] > 0
    assert all(b < 0.5 * a for a, b in zip(errs, errs[1:]))        # about 4x per level
    assert errs[-1] < 0.07


def test_full_mass_converges_from_above():
    V, F = icosphere(3)
    assert (eigenvalues(V, F, 15, mass="full") > SPHERE).all()


def test_eigenvectors_are_mass_orthonormal_and_solve_the_pencil():
    V, F = icosphere(3)
    from sns_np.mesh import cotan_laplacian

    for mass, kind in (("full", "full"), ("lumped", "barycentric"), ("voronoi", "voronoi")):
        lam, phi = laplacian_eigenmodes(V, F, 8, mass=mass, return_vectors=True)
        M = mass_matrix(V, F, kind)
        assert abs(phi.T @ M @ phi - np.eye(8)).max() < 1e-10
        R = -(cotan_laplacian(V, F) @ phi) - (M @ phi) * lam
        assert np.abs(R).max() < 1e-9
        # non-constant modes are orthogonal to constants
        assert abs(np.ones(len(V)) @ M @ phi).max() < 1e-10


def test_scaling_by_radius():
    V, F = icosphere(3)
    assert eigenvalues(3 * V, F, 4) == pytest.approx(eigenvalues(V, F, 4) / 9, rel=1e-9)


def test_deterministic():
    V, F = icosphere(2)
    a = laplacian_eigenmodes(V, F, 5, return_vectors=True)
    b = laplacian_eigenmodes(V, F, 5, return_vectors=True)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_bad_input():
    V, F = icosphere(0)
    with pytest.raises(ValueError, match="k must be <= n - 2 = 10"):
        eigenvalues(V, F, 11)
    with pytest.raises(ValueError, match="k must be an integer >= 1"):
        eigenvalues(V, F, 0)
    with pytest.raises(ValueError, match="unknown mass"):
        eigenvalues(V, F, 3, mass="diag")


@pytest.mark.data
def test_uv_sphere_radius(mesh_dir):
    V, F = load(mesh_dir / "uv_sphere.obj")               # radius 0.7, 20 x 19 segments
    lam = eigenvalues(V, F, 8) * 0.7 ** 2
    assert np.abs(lam - SPHERE[:8]).max() < 0.3
    assert (lam > SPHERE[:8]).all()


def test_repeated_eigenvalues_at_the_edge_are_all_found():
    """Lanczos once returned the icosphere's 5-fold eigenvalue 6.07 only 4 times for k = 8
    (and 12.2 instead); the dense solver is the reference."""
    import scipy.linalg

    from sns_np.mesh import cotan_laplacian, icosphere, mass_matrix
    V, F = icosphere(2)
    ref = scipy.linalg.eigh(-cotan_laplacian(V, F).toarray(),
                            mass_matrix(V, F, "full").toarray(), eigvals_only=True)
    for k in (8, 20, 29, 34):
        assert np.allclose(laplacian_eigenmodes(V, F, k), ref[1:k + 1], rtol=1e-8), k
