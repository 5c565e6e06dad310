"""Sphere sampling, rejection sampling by area element, and integrals over a surface map.

Every surface integral is a weighted sum over sphere points ``p_i`` (paper Eq. 28, Sec. 5):

    integral over S of h dA  ~=  sum_i w_i g(p_i),          h(S(p)) = g(p),

held by a :class:`SurfaceSample` together with the per-point geometry that integrands need
(the frame ``R``, the inverse metric ``I^-1`` and the area element ``sqrt(det I)``). Three
kinds of sample, chosen with ``method=``:

``"mc"``         uniform sphere points (normalised Gaussians), ``w_i = 4 pi d_i / n``
``"rejection"``  points uniform in surface area (the paper's rejection sampling), ``w_i = A / N``
``"quadrature"`` the deterministic product rule of :mod:`sns_np.quadrature`, ``w_i = v_i d_i``

Monte Carlo estimates come with standard errors (:class:`Estimate`); quadrature estimates
have none (``stderr`` is NaN) and are the low-noise choice for evaluation.

Examples
--------
>>> from sns_np.shapes import Sphere
>>> est = area(Sphere(2.0), n=20000, rng=0)           # 16 pi = 50.27
>>> bool(abs(est.value - 16 * np.pi) < 4 * est.stderr + 1e-9)
True
>>> round(area(Sphere(2.0), method="quadrature").value, 10) == round(16 * np.pi, 10)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._validation import (
    as_generator,
    check_choice,
    check_positive_float,
    check_positive_int,
)
from .errors import ShapeError
from .geometry import (
    area_element_from_jets,
    first_fundamental_form_from_jets,
    inverse_metric,
    tangent_frame,
)
from .geometry.chart import CHUNK, DEGENERATE_TOL, chart_jet_chunks
from .protocol import chunk_slices, field_jet

__all__ = [
    "uniform_sphere", "fibonacci_sphere", "Estimate", "surface_geometry", "SurfaceSample",
    "surface_sample",
    "rejection_sample", "area", "integrate", "inner_product", "l2_norm", "rayleigh_quotient",
    "METHODS",
]

METHODS = ("mc", "rejection", "quadrature")
_FOUR_PI = 4.0 * math.pi


# ------------------------------------------------------------------------------ sphere points

def uniform_sphere(n: int, rng=None) -> np.ndarray:
    """``n`` independent points uniform on the unit sphere: normalised 3D Gaussians.

    Parameters
    ----------
    n : int >= 0
    rng : None, int or numpy.random.Generator (``None`` means seed 0)

    Returns
    -------
    p : (n, 3) float array, ``|p| = 1`` to round-off

    Examples
    --------
    >>> p = uniform_sphere(5, rng=1)
    >>> p.shape, bool(np.allclose(np.linalg.norm(p, axis=1), 1.0))
    ((5, 3), True)
    """
    n = check_positive_int(n, "n", minimum=0)
    gen = as_generator(rng)
    p = gen.standard_normal((n, 3))
    r = np.linalg.norm(p, axis=1)
    bad = r < 1e-12
    while bad.any():  # probability ~1e-36 per point; redraw instead of dividing by zero
        p[bad] = gen.standard_normal((int(bad.sum()), 3))
        r = np.linalg.norm(p, axis=1)
        bad = r < 1e-12
    return p / r[:, None]


def fibonacci_sphere(n: int) -> np.ndarray:
    """Deterministic low-discrepancy points: the Fibonacci (golden-angle) spiral.

    ``z_i = 1 - (2 i + 1) / n`` (equal-area latitude bands, by Archimedes' theorem) and
    ``phi_i = i * pi (3 - sqrt 5)``. Equal-weight averages over these points converge
    faster than Monte Carlo for smooth integrands (about ``n^-3/4`` for the spherical cap
    discrepancy), with no randomness.

    Parameters
    ----------
    n : int >= 1

    Returns
    -------
    p : (n, 3) float array of unit vectors

    References
    ----------
    R. Swinbank and R. J. Purser, "Fibonacci grids: a novel approach to global modelling",
    Q. J. R. Meteorol. Soc. 132, 2006.

    Examples
    --------
    >>> p = fibonacci_sphere(1000)
    >>> bool(abs(p[:, 2].mean()) < 1e-12), bool(abs((p[:, 0] ** 2).mean() - 1 / 3) < 1e-3)
    (True, True)
    """
    n = check_positive_int(n, "n")
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    rho = np.sqrt(np.clip((1.0 - z) * (1.0 + z), 0.0, None))
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


# ------------------------------------------------------------------------------ estimates

@dataclass(frozen=True)
class Estimate:
    """A number with its standard error (NaN for deterministic quadrature).

    Examples
    --------
    >>> Estimate(2.0, 0.1)
    Estimate(value=2.0, stderr=0.1)
    >>> float(Estimate(2.0, 0.1))
    2.0
    """

    value: float
    stderr: float

    def __float__(self):
        return float(self.value)


# ------------------------------------------------------------------------------ geometry

def surface_geometry(surface, p, chunk=CHUNK, tol=DEGENERATE_TOL):
    """``x``, ``R``, ``I^-1`` and ``sqrt(det I)`` at unit points ``p``; raises on degeneracy.

    Parameters
    ----------
    surface : surface map
    p : (n, 3) float array of unit vectors
    chunk : int, points per call of the map
    tol : float, the degeneracy threshold of :func:`sns_np.geometry.chart.degenerate_mask`

    Returns
    -------
    x : (n, 3), R : (n, 3, 2), Iinv : (n, 2, 2), area_element : (n,) float arrays

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> x, R, Iinv, d = surface_geometry(Sphere(2.0), fibonacci_sphere(4))
    >>> d
    array([4., 4., 4., 4.])
    """
    n = p.shape[0]
    x = np.empty((n, 3))
    R = tangent_frame(p)
    Iinv = np.empty((n, 2, 2))
    d = np.empty(n)
    for sl, (y, JR), _ in chart_jet_chunks(surface, p, 1, R=R, chunk=chunk, tol=tol, detail=(
            f"sigma_min / sigma_max of J R is below {tol:g}; integrals and the "
            f"Laplace-Beltrami operator need a regular parametrisation")):
        I = first_fundamental_form_from_jets(JR)
        x[sl], Iinv[sl], d[sl] = y, inverse_metric(I), area_element_from_jets(JR)
    return x, R, Iinv, d


def _area_elements(surface, p, chunk=CHUNK, tol=DEGENERATE_TOL):
    return surface_geometry(surface, p, chunk, tol)[3]


# ------------------------------------------------------------------------------ samples

@dataclass
class SurfaceSample:
    """Sphere points with integration weights and the surface geometry integrands need.

    ``integral over S of h dA ~= sum_i weights[i] * g(p[i])`` for ``h(S(p)) = g(p)``.

    Attributes
    ----------
    p : (n, 3) float array, unit sphere points
    x : (n, 3) float array, surface points ``S(p)``
    R : (n, 3, 2) float array, the tangent frame of :func:`sns_np.geometry.tangent_frame`
    Iinv : (n, 2, 2) float array, inverse first fundamental form in that frame
    area_element : (n,) float array, ``sqrt(det I)``
    weights : (n,) float array
    kind : {"mc", "rejection", "quadrature"}
    area : float, the estimated surface area (``weights.sum()`` except for "rejection", where
        it comes from all proposals)
    area_stderr : float, its standard error (NaN for "quadrature")
    n_proposed : int, sphere points evaluated to build the sample

    Examples
    --------
    >>> from sns_np.sampling import surface_sample
    >>> from sns_np.shapes import Sphere
    >>> s = surface_sample(Sphere(2.0), 2000, method="mc", rng=0)
    >>> s.p.shape, s.R.shape, s.Iinv.shape
    ((2000, 3), (2000, 3, 2), (2000, 2, 2))
    >>> area = s.integral(np.ones(len(s)))             # 4 pi r^2 = 50.27
    >>> bool(abs(area.value - 16 * np.pi) < 1e-9)      # exact: a sphere's area element is constant
    True
    """

    p: np.ndarray
    x: np.ndarray
    R: np.ndarray
    Iinv: np.ndarray
    area_element: np.ndarray
    weights: np.ndarray
    kind: str
    area: float
    area_stderr: float
    n_proposed: int

    def __len__(self):
        return self.p.shape[0]

    def subset(self, idx) -> SurfaceSample:
        """A sub-sample (a training mini-batch); weights rescaled so sums stay unbiased.

        Examples
        --------
        >>> from sns_np.sampling import surface_sample
        >>> from sns_np.shapes import Ellipsoid
        >>> s = surface_sample(Ellipsoid(1.0, 2.0, 3.0), 1000, rng=0)
        >>> batch = s.subset(np.arange(100))
        >>> len(batch), bool(np.isclose(batch.weights.sum(), s.weights[:100].sum() * 10))
        (100, True)
        """
        idx = np.asarray(idx)
        m = self.p[idx].shape[0]
        if m == 0:
            raise ValueError("subset needs at least one point")
        scale = len(self) / m if self.kind != "quadrature" else 1.0
        return SurfaceSample(self.p[idx], self.x[idx], self.R[idx], self.Iinv[idx],
                             self.area_element[idx], self.weights[idx] * scale, self.kind,
                             self.area, self.area_stderr, self.n_proposed)

    # -------------------------------------------------------------- integrands
    def values(self, field, domain: str = "sphere") -> np.ndarray:
        """``g(p_i)`` (n,) of a field (protocol object) or of a callable ``f(p) -> (n,)``.

        Examples
        --------
        >>> from sns_np.sampling import surface_sample
        >>> from sns_np.shapes import Sphere, SphericalHarmonic
        >>> s = surface_sample(Sphere(), 4, rng=0)
        >>> Y10 = np.sqrt(3 / (4 * np.pi)) * s.p[:, 2]
        >>> bool(np.allclose(s.values(SphericalHarmonic(1, 0)), Y10))
        True
        >>> bool(np.allclose(s.values(lambda p: p[:, 0]), s.p[:, 0]))     # a plain callable too
        True
        """
        return _field(field, self, domain, 0)

    def dirichlet_density(self, field, domain: str = "sphere"):
        """``|grad_S h|^2 = (R^T grad g)^T I^-1 (R^T grad g)`` (n,), and ``g`` (n,).

        The surface gradient of ``h(S(p)) = g(p)`` is ``J R I^-1 R^T grad g`` (paper Eq. 24,
        ``grad h = (J^T)^-1 grad g`` restricted to the tangent plane), so its squared length
        needs only the precomputed ``R`` and ``I^-1``.

        Examples
        --------
        >>> from sns_np.sampling import surface_sample
        >>> from sns_np.shapes import Sphere, SphericalHarmonic
        >>> s = surface_sample(Sphere(), 800, method="quadrature")
        >>> d, g = s.dirichlet_density(SphericalHarmonic(1, 1))
        >>> round(s.integral(d).value, 6)          # int |grad Y_1|^2 = l(l+1) int Y^2 = 2
        2.0
        """
        g, grad = _field(field, self, domain, 1)
        G = np.einsum("kab,ka->kb", self.R, grad)
        return np.einsum("ka,kab,kb->k", G, self.Iinv, G), g

    # -------------------------------------------------------------- estimators
    def integral(self, values) -> Estimate:
        """``integral over S of h dA`` from values ``g(p_i)`` (n,), with its standard error.

        Examples
        --------
        >>> from sns_np.sampling import surface_sample
        >>> from sns_np.shapes import Ellipsoid
        >>> s = surface_sample(Ellipsoid(1.0, 2.0, 3.0), 20000, rng=0)
        >>> est = s.integral(np.ones(len(s)))                     # the area, 48.88
        >>> round(est.value, 1), bool(abs(est.value - 48.88) < 4 * est.stderr)
        (48.8, True)
        """
        f = self._check(values, "values")
        value = float(self.weights @ f)
        if self.kind == "quadrature":
            return Estimate(value, math.nan)
        n = len(self)
        if n < 2:
            return Estimate(value, math.nan)
        t = n * self.weights * f  # i.i.d. terms with mean = the integral
        se = float(np.std(t, ddof=1) / math.sqrt(n))
        if self.kind == "rejection":  # the area itself is an estimate
            se = math.hypot(se, float(f.mean()) * self.area_stderr)
        return Estimate(value, se)

    def ratio(self, numerator, denominator) -> Estimate:
        """``integral a dA / integral b dA`` with a delta-method standard error.

        ``se = std(t_a - r t_b) / (sqrt(n) mean(t_b))`` for the i.i.d. terms ``t = n w f``;
        the uncertainty of the area cancels.

        Examples
        --------
        >>> from sns_np.sampling import surface_sample
        >>> from sns_np.shapes import Sphere
        >>> s = surface_sample(Sphere(), 400, method="quadrature")
        >>> z2 = s.p[:, 2] ** 2
        >>> round(s.ratio(z2, np.ones(len(s))).value, 6)           # mean of z^2 on the sphere: 1/3
        0.333333
        """
        a = self._check(numerator, "numerator")
        b = self._check(denominator, "denominator")
        den = float(self.weights @ b)
        if den == 0.0:
            raise ValueError("the denominator integrates to zero (a zero field?)")
        r = float(self.weights @ a) / den
        n = len(self)
        if self.kind == "quadrature" or n < 2:
            return Estimate(r, math.nan)
        t = n * self.weights * (a - r * b)
        return Estimate(r, float(np.std(t, ddof=1) / math.sqrt(n) / abs(den)))

    def _check(self, values, name):
        f = np.asarray(values, dtype=np.float64)
        if f.shape != (len(self),):
            raise ShapeError(f"{name} must have shape ({len(self)},) (one value per sample "
                             f"point), got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise ShapeError(f"{name} contains non-finite values")
        return f


def _field(field, sample, domain, order):
    """Value (and gradient) of a field on the sample; the gradient is w.r.t. the sphere point."""
    check_choice(domain, "domain", {"sphere", "ambient"})
    if domain == "ambient":
        raise ValueError("this function takes fields on the sphere (domain='sphere'); wrap an "
                         "ambient field f as sns_np.shapes.PullbackField(f, surface)")
    if not callable(getattr(field, "jet", None)):
        if order == 0 and callable(field):
            return sample._check(field(sample.p), "field(p)")
        raise TypeError(f"field must follow the field protocol (jet(p, order)); got "
                        f"{type(field).__name__}")
    n = len(sample)
    if order == 0:
        out = np.empty(n)
        for sl in chunk_slices(n, CHUNK):
            out[sl] = field_jet(field, sample.p[sl], 0)
        return out
    g, grad = np.empty(n), np.empty((n, 3))
    for sl in chunk_slices(n, CHUNK):
        g[sl], grad[sl] = field_jet(field, sample.p[sl], 1)
    return g, grad


def surface_sample(surface, n: int = 100_000, method: str = "mc", rng=None) -> SurfaceSample:
    """Sample points and weights for integrals over the surface ``S(sphere)``.

    Parameters
    ----------
    surface : surface map (``jet(p, order)``)
    n : int
        ``"mc"``: number of uniform sphere points; ``"rejection"``: expected number of
        points (``n_target`` of :func:`rejection_sample`); ``"quadrature"``: about ``n``
        nodes (``n_theta = ceil(sqrt(n / 2))``, ``n_phi = 2 n_theta``).
    method : {"mc", "rejection", "quadrature"}
    rng : None, int or numpy.random.Generator (ignored by "quadrature")

    Returns
    -------
    SurfaceSample

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> s = surface_sample(Ellipsoid(1.0, 2.0, 3.0), 512, method="quadrature")
    >>> len(s), s.kind
    (512, 'quadrature')
    """
    check_choice(method, "method", METHODS)
    n = check_positive_int(n, "n")
    if method == "rejection":
        return rejection_sample(surface, n, rng)
    if method == "quadrature":
        from .quadrature import sphere_quadrature
        nt = max(1, math.ceil(math.sqrt(n / 2)))
        p, v = sphere_quadrature(nt)
        x, R, Iinv, d = surface_geometry(surface, p)
        w = v * d
        return SurfaceSample(p, x, R, Iinv, d, w, "quadrature", float(w.sum()), math.nan,
                             p.shape[0])
    p = uniform_sphere(n, rng)
    x, R, Iinv, d = surface_geometry(surface, p)
    w = _FOUR_PI * d / n
    se = _FOUR_PI * float(np.std(d, ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    return SurfaceSample(p, x, R, Iinv, d, w, "mc", float(w.sum()), se, n)


def rejection_sample(surface, n_target: int, rng=None, *, oversample: float = 10.0,
                     max_proposals: int = 20_000_000) -> SurfaceSample:
    """Sphere points whose images are uniform in surface area (paper Sec. 5, steps i-iv).

    1. Draw ``n_prop`` uniform sphere points ``p_j`` (normalised Gaussians, ``n_prop =
       oversample * n_target`` to start).
    2. Evaluate the area element ``d_j = sqrt(det I)`` at these unit points.
    3. Keep ``p_j`` with probability ``n_target d_j / sum_k d_k``; the expected number of
       points is exactly ``n_target``. Where that probability would exceed 1 (a very uneven
       area element), more proposals are drawn until it does not, so no point is clipped.
    4. Push the kept points through the map.

    Unlike the reference implementation, the density is evaluated at the normalised points,
    and the returned points lie on the sphere.

    Parameters
    ----------
    surface : surface map
    n_target : int >= 1, expected number of points
    rng : None, int or numpy.random.Generator
    oversample : float >= 1, initial proposals per target point
    max_proposals : int, limit on ``M``

    Returns
    -------
    SurfaceSample
        With ``kind="rejection"``, equal weights ``area / N`` where
        ``area = 4 pi mean(d_j)`` is estimated from all ``M`` proposals (``area_stderr`` its
        standard error) and ``N`` is the number of accepted points.

    Raises
    ------
    DegenerateMapError
        If the map's Jacobian is (near-)singular at a proposal.
    ValueError
        If the area element is so uneven that more than ``max_proposals`` points would be
        needed.

    Examples
    --------
    >>> from sns_np.shapes import Ellipsoid
    >>> s = rejection_sample(Ellipsoid(1.0, 1.0, 3.0), 2000, rng=0)
    >>> bool(abs(len(s) - 2000) < 200), bool(np.allclose(np.linalg.norm(s.p, axis=1), 1))
    (True, True)
    """
    n_target = check_positive_int(n_target, "n_target")
    oversample = check_positive_float(oversample, "oversample")
    if oversample < 1.0:
        raise ValueError(f"oversample must be >= 1, got {oversample}")
    max_proposals = check_positive_int(max_proposals, "max_proposals")
    gen = as_generator(rng)
    n_prop = max(int(math.ceil(oversample * n_target)), 2)
    if n_prop > max_proposals:
        raise ValueError(f"oversample * n_target = {n_prop} exceeds max_proposals = "
                         f"{max_proposals}")
    P = uniform_sphere(n_prop, gen)
    d = _area_elements(surface, P)
    while n_target * d.max() > d.sum():
        if 2 * P.shape[0] > max_proposals:
            raise ValueError(
                f"the area element varies too much for rejection sampling: max/mean = "
                f"{d.max() / d.mean():.3g}, so n_target = {n_target} needs more than "
                f"max_proposals = {max_proposals} proposals; lower n_target or raise "
                f"max_proposals")
        extra = uniform_sphere(P.shape[0], gen)
        P = np.concatenate([P, extra])
        d = np.concatenate([d, _area_elements(surface, extra)])
    n_prop = P.shape[0]
    keep = gen.random(n_prop) < n_target * d / d.sum()
    p = P[keep]
    if p.shape[0] == 0:
        raise ValueError(f"no point was accepted (n_target = {n_target}); use a larger n_target")
    area_mc = _FOUR_PI * float(d.mean())
    area_se = _FOUR_PI * float(np.std(d, ddof=1)) / math.sqrt(n_prop)
    x, R, Iinv, dk = surface_geometry(surface, p)
    N = p.shape[0]
    return SurfaceSample(p, x, R, Iinv, dk, np.full(N, area_mc / N), "rejection", area_mc,
                         area_se, n_prop)


# ------------------------------------------------------------------------------ integrals

def _get_sample(surface, sample, n, method, rng):
    if sample is not None:
        if not isinstance(sample, SurfaceSample):
            raise TypeError(f"sample must be a SurfaceSample, got {type(sample).__name__}")
        return sample
    return surface_sample(surface, n, method, rng)


def area(surface, n: int = 100_000, method: str = "mc", rng=None, *,
         sample: SurfaceSample | None = None) -> Estimate:
    """Surface area ``integral over S^2 of sqrt(det I) dsigma``.

    ``"mc"``: ``4 pi mean(d_i)`` over uniform sphere points, ``se = 4 pi std(d) / sqrt(n)``.
    ``"quadrature"``: the product Gauss rule (no standard error). ``"rejection"``: the area
    estimated from all proposals of :func:`rejection_sample`.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> bool(np.isclose(area(Sphere(), method="quadrature").value, 4 * np.pi))
    True
    """
    s = _get_sample(surface, sample, n, method, rng)
    return Estimate(s.area, s.area_stderr)


def integrate(surface, field, n: int = 100_000, method: str = "mc", rng=None, *,
              sample: SurfaceSample | None = None) -> Estimate:
    """``integral over S of h dA`` for the surface field ``h(S(p)) = g(p)``.

    Parameters
    ----------
    surface : surface map
    field : field on the sphere (``jet(p, order)``) or a callable ``g(p) -> (n,)``
    n, method, rng : see :func:`surface_sample`
    sample : SurfaceSample, optional; reuse points (``n``, ``method``, ``rng`` are ignored)

    Returns
    -------
    Estimate

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> est = integrate(Sphere(), lambda p: p[:, 2] ** 2, method="quadrature")
    >>> bool(np.isclose(est.value, 4 * np.pi / 3))
    True
    """
    s = _get_sample(surface, sample, n, method, rng)
    return s.integral(s.values(field))


def inner_product(surface, f, g, n: int = 100_000, method: str = "mc", rng=None, *,
                  sample: SurfaceSample | None = None) -> Estimate:
    """``<f, g>_{L^2(S)} = integral over S of f g dA`` (paper Eq. 18).

    Examples
    --------
    >>> from sns_np.shapes import Sphere, SphericalHarmonic
    >>> est = inner_product(Sphere(), SphericalHarmonic(2, 1), SphericalHarmonic(2, 1),
    ...                     method="quadrature")
    >>> bool(np.isclose(est.value, 1.0))
    True
    """
    s = _get_sample(surface, sample, n, method, rng)
    return s.integral(s.values(f) * s.values(g))


def l2_norm(surface, f, n: int = 100_000, method: str = "mc", rng=None, *,
            sample: SurfaceSample | None = None) -> Estimate:
    """``||f||_{L^2(S)} = sqrt(integral f^2 dA)`` (paper Eq. 19), with
    ``se = se(integral f^2) / (2 ||f||)``.

    Examples
    --------
    >>> from sns_np.shapes import Sphere
    >>> bool(np.isclose(l2_norm(Sphere(), lambda p: np.ones(len(p)), method="quadrature").value,
    ...                 np.sqrt(4 * np.pi)))
    True
    """
    s = _get_sample(surface, sample, n, method, rng)
    sq = s.integral(s.values(f) ** 2)
    norm = math.sqrt(max(sq.value, 0.0))
    return Estimate(norm, sq.stderr / (2 * norm) if norm > 0 else math.nan)


def rayleigh_quotient(surface, f, n: int = 100_000, method: str = "mc", rng=None, *,
                      sample: SurfaceSample | None = None) -> Estimate:
    """``Q(h) = ||grad_S h||^2 / ||h||^2`` (paper Eq. 20) for ``h(S(p)) = f(p)``.

    For an eigenfunction ``Delta_S h = -lambda h`` it equals ``lambda``. The field needs a
    first-order jet. The standard error is the delta-method error of the ratio.

    Examples
    --------
    >>> from sns_np.shapes import Sphere, SphericalHarmonic
    >>> q = rayleigh_quotient(Sphere(), SphericalHarmonic(3, -2), method="quadrature")
    >>> bool(np.isclose(q.value, 12.0))
    True
    """
    s = _get_sample(surface, sample, n, method, rng)
    dens, g = s.dirichlet_density(f)
    return s.ratio(dens, g * g)
