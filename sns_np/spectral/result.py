"""The result of an eigenmode computation, and its export onto a mesh."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .._validation import as_points, check_positive_int
from ..protocol import field_jet

__all__ = ["EigenResult", "eigenmodes_on_mesh"]


@dataclass
class EigenResult:
    """Laplace-Beltrami eigenpairs ``Delta_S phi_i = -lambda_i phi_i`` of a surface map.

    Attributes
    ----------
    eigenvalues : (k,) float array, ascending, the constant mode excluded
    eigenfunctions : list of k fields on the sphere (``jet(p, order)``, ``__call__(p)``),
        ``phi_i(S(p)) = eigenfunctions[i](p)``, of unit ``L^2(S)`` norm
    method : {"ritz", "neural"}
    constant_eigenvalue : float, the computed eigenvalue of the constant mode (0 up to
        round-off for "ritz"; exactly 0 for "neural", which projects constants out)
    constant_value : float, ``1 / sqrt(area)``, the unit-norm constant eigenfunction
    area : float, surface area used for the normalisation
    stderr : (k,) float array or None, Monte Carlo standard errors of the eigenvalues
        ("neural")
    converged : bool
    convergence : float, "ritz": max relative change of the k eigenvalues from degree
        ``L - 2`` to ``L``; "neural": max relative standard error
    seconds : float, wall time
    info : dict, method-specific details (degree, quadrature size, losses, timings, ...)
    evaluator : callable, optional, ``p -> (n, k)`` values of all eigenfunctions at once (a
        faster path than evaluating the fields one by one)

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> from sns_np.spectral import eigenmodes
    >>> res = eigenmodes(Sphere(), 3, method="ritz", L=4)
    >>> res.eigenvalues.round(8)
    array([2., 2., 2.])
    >>> res(np.array([[0.0, 0.0, 1.0]])).shape
    (1, 3)
    """

    eigenvalues: np.ndarray
    eigenfunctions: list
    method: str
    constant_eigenvalue: float
    constant_value: float
    area: float
    stderr: np.ndarray | None = None
    converged: bool = True
    convergence: float = float("nan")
    seconds: float = 0.0
    info: dict = field(default_factory=dict)
    evaluator: Callable | None = field(default=None, repr=False)

    @property
    def k(self) -> int:
        return int(self.eigenvalues.shape[0])

    def __len__(self):
        return self.k

    def evaluate(self, p) -> np.ndarray:
        """All eigenfunctions at sphere points ``p`` (n, 3), as an (n, k) array.

        Examples
        --------
        >>> from sns_np.shapes import Sphere
        >>> from sns_np.spectral import eigenmodes
        >>> res = eigenmodes(Sphere(), 3, L=2)
        >>> phi = res.evaluate(np.eye(3))                 # the modes at the three axis points
        >>> phi.shape                   # an orthonormal basis of the l = 1 eigenspace, so that
        (3, 3)
        >>> bool(np.allclose((phi ** 2).sum(axis=1), 3 / (4 * np.pi)))   # sum phi_i^2 = 3 / (4 pi)
        True
        """
        p = as_points(p, "p")
        if self.evaluator is not None:
            return self.evaluator(p)
        return np.stack([field_jet(f, p, 0) for f in self.eigenfunctions], axis=1) \
            if self.eigenfunctions else np.zeros((p.shape[0], 0))

    __call__ = evaluate

    def summary(self) -> str:
        """The eigenvalues and convergence in a few lines of text.

        Examples
        --------
        >>> from sns_np.shapes import Sphere
        >>> from sns_np.spectral import eigenmodes
        >>> print(eigenmodes(Sphere(), 3, L=4).summary())
        ritz eigenmodes: k = 3, area 12.5664, ... s, converged True (indicator ...)
          lambda_1   = 2
          lambda_2   = 2
          lambda_3   = 2
        """
        lines = [f"{self.method} eigenmodes: k = {self.k}, area {self.area:.6g}, "
                 f"{self.seconds:.1f} s, converged {self.converged} "
                 f"(indicator {self.convergence:.2e})"]
        for i, lam in enumerate(self.eigenvalues):
            se = "" if self.stderr is None else f" +- {self.stderr[i]:.2g}"
            lines.append(f"  lambda_{i + 1:<3d} = {lam:.8g}{se}")
        return "\n".join(lines)


def eigenmodes_on_mesh(result: EigenResult, surface, level: int = 5):
    """Eigenfunctions as per-vertex fields on an icosphere pushed through the surface.

    What ``sns-np eigen model.npz -k 10 -o modes.ply`` writes.

    Parameters
    ----------
    result : EigenResult
    surface : surface map (the one the modes were computed on)
    level : int, icosphere level (``10 * 4^level + 2`` vertices)

    Returns
    -------
    V : (n, 3) float array, ``S(icosphere vertices)``
    F : (m, 3) int array
    fields : dict ``{"mode_1": (n,) array, ...}`` (``mode_i`` has eigenvalue
        ``result.eigenvalues[i - 1]``), plus ``"sphere_x"``, ``"sphere_y"``, ``"sphere_z"``,
        the parameter-sphere coordinates of each vertex

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> from sns_np.spectral import eigenmodes
    >>> S = Ellipsoid(1.0, 1.3, 0.7)
    >>> V, F, fields = eigenmodes_on_mesh(eigenmodes(S, 2, method="ritz", L=6), S, level=2)
    >>> V.shape, sorted(fields)[:2]
    ((162, 3), ['mode_1', 'mode_2'])
    """
    from ..mesh import icosphere
    from ..protocol import surface_jet

    if not isinstance(result, EigenResult):
        raise TypeError(f"result must be an EigenResult, got {type(result).__name__}")
    P, F = icosphere(check_positive_int(level, "level", minimum=0))
    V = surface_jet(surface, P, 0)
    vals = result.evaluate(P)
    fields = {f"mode_{i + 1}": vals[:, i].copy() for i in range(result.k)}
    fields.update(sphere_x=P[:, 0].copy(), sphere_y=P[:, 1].copy(), sphere_z=P[:, 2].copy())
    return V, F, fields
