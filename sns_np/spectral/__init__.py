"""Laplace-Beltrami eigenmodes of a surface map (paper Sec. 5).

``Delta_S phi = -lambda phi`` with ``lambda`` reported positive; the constant mode
(``lambda_0 = 0``) is excluded from the results and reported separately. Two methods:

``"ritz"`` (:func:`ritz_eigenmodes`)
    Rayleigh-Ritz in spherical harmonics up to degree ``L`` pulled back through the map; all
    ``k`` modes at once, deterministic, spectrally accurate for smooth maps, with a
    convergence indicator. The eigenfunctions are :class:`HarmonicField` objects.
``"neural"`` (:func:`neural_eigenmodes`)
    The paper's method: one small network per mode, trained sequentially on the Rayleigh
    quotient with orthogonality and unit-norm penalties. The eigenfunctions are
    :class:`~sns_np.fields.NeuralField` objects; their losses (paper Eqs. 25-27, with
    hand-written parameter gradients) are :func:`eigen_loss` and its parts
    :func:`rayleigh_loss`, :func:`orthogonality_loss`, :func:`unit_norm_loss`.

Mesh reference: :func:`mesh_eigenvalues`, :func:`fem_eigenvalues` (cotangent FEM on the
icosphere pushed through the map) and :func:`richardson`. Export: :func:`eigenmodes_on_mesh`.

Examples
--------
>>> from sns_np.shapes import Sphere
>>> res = eigenmodes(Sphere(), 8, method="ritz")
>>> res.eigenvalues.round(6)                       # l(l+1) with multiplicity 2l+1
array([2., 2., 2., 6., 6., 6., 6., 6.])
"""

from __future__ import annotations

from .._validation import check_choice, check_positive_int
from .fem import fem_eigenvalues, mesh_eigenvalues, richardson
from .harmonics import HarmonicField, n_harmonics, real_sh, sh_index
from .losses import EigenLoss, eigen_loss, orthogonality_loss, rayleigh_loss, unit_norm_loss
from .neural import neural_eigenmodes
from .result import EigenResult, eigenmodes_on_mesh
from .ritz import assemble, default_degree, ritz_eigenmodes

__all__ = [
    "eigenmodes", "EigenResult", "eigenmodes_on_mesh", "ritz_eigenmodes", "neural_eigenmodes",
    "assemble", "default_degree", "HarmonicField", "real_sh", "sh_index", "n_harmonics",
    "mesh_eigenvalues", "fem_eigenvalues", "richardson", "METHODS",
    "EigenLoss", "eigen_loss", "rayleigh_loss", "orthogonality_loss", "unit_norm_loss",
]

METHODS = ("ritz", "neural")


def eigenmodes(surface, k: int, method: str = "ritz", rng=None, **options) -> EigenResult:
    """The ``k`` smallest non-zero Laplace-Beltrami eigenpairs of a surface map.

    Parameters
    ----------
    surface : surface map (``jet(p, order)``; a SphericalNeuralSurface, an analytic shape)
    k : int >= 1, number of non-constant modes
    method : {"ritz", "neural"}
    rng : None, int or numpy.random.Generator; used by "neural" (``None`` means seed 0),
        ignored by the deterministic "ritz"
    **options
        Passed to :func:`ritz_eigenmodes` (``L``, ``tol``, ``L_max``, ``n_theta``,
        ``progress``) or :func:`neural_eigenmodes` (``steps``, ``batch``, ``lr``, ...).

    Returns
    -------
    EigenResult
        ``eigenvalues`` (k,) ascending, ``eigenfunctions`` (k fields on the sphere, unit
        ``L^2(S)`` norm), ``constant_eigenvalue``, ``convergence`` and ``info``.

    Raises
    ------
    ValueError
        Unknown method, ``k < 1``, ``k`` beyond what the basis resolves ("ritz").
    DegenerateMapError
        The map's Jacobian is (near-)singular at a sample or quadrature point.
    DivergenceError
        The neural optimisation produced non-finite values (partial result attached).

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> res = eigenmodes(Ellipsoid(1.0, 1.3, 0.7), 3)
    >>> res.eigenvalues.round(4)
    array([1.5696, 2.1382, 2.5225])
    """
    check_choice(method, "method", METHODS)
    k = check_positive_int(k, "k")
    if method == "ritz":
        return ritz_eigenmodes(surface, k, **options)
    return neural_eigenmodes(surface, k, rng=rng, **options)
