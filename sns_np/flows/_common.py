"""Shared pieces of the flows (private): time grids, sample points, the stability limit
and atomic output folders (the least-squares read-out is
:meth:`sns_np.nn.ResidualMLP.fit_readout`)."""

from __future__ import annotations

import math
import warnings

import numpy as np

from .._atomic import write_folder
from .._validation import check_choice, check_positive_float
from ..options import DEFAULT_SCHEME, DEFAULT_SNAPSHOTS, SCHEMES
from ..sampling import fibonacci_sphere

STABILITY_MODES = ("warn", "raise", "ignore")


class StabilityWarning(RuntimeWarning):
    """A time step exceeds the stability limit of an explicit scheme."""


def check_times(t_end, dt, times=None, n_snapshots=DEFAULT_SNAPSHOTS):
    """Validated ``t_end``, ``dt`` and the ascending snapshot times (start 0, end ``t_end``)."""
    t_end = check_positive_float(t_end, "t_end")
    dt = check_positive_float(dt, "dt")
    if times is None:
        n = int(n_snapshots)
        if n < 1:
            raise ValueError(f"n_snapshots must be an integer >= 1, got {n_snapshots!r}")
        return t_end, dt, np.linspace(0.0, t_end, n + 1)
    T = np.asarray(times, dtype=np.float64).ravel()
    if T.size == 0 or not np.all(np.isfinite(T)):
        raise ValueError(f"times must be finite numbers, got {times!r}")
    if T.min() < 0 or T.max() > t_end * (1 + 1e-12):
        raise ValueError(f"times must lie in [0, t_end = {t_end:g}], got [{T.min():g}, "
                         f"{T.max():g}]")
    T = np.unique(np.concatenate([[0.0], T, [t_end]]))
    return t_end, dt, T


def substeps(t0, t1, dt):
    """Equal steps of at most ``dt`` from ``t0`` to ``t1`` (so snapshots land exactly)."""
    m = max(1, math.ceil((t1 - t0) / dt - 1e-9))
    return [(t1 - t0) / m] * m


def random_rotation(rng):
    """A uniformly random rotation matrix (3, 3) (QR of a Gaussian matrix, sign-fixed)."""
    Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def step_points(n, rng):
    """``n`` near-uniform sphere points: a Fibonacci lattice under a fresh random rotation.

    Every step sees a different point set, so a refitted network cannot settle on one lattice.
    """
    return fibonacci_sphere(n) @ random_rotation(rng).T


# SCHEMES (the explicit time schemes and their Runge-Kutta coefficients), DEFAULT_SCHEME and
# DEFAULT_SNAPSHOTS live in sns_np.options, with the other choices a user makes

#: length of the real stability interval ``[-c, 0]`` of each scheme's amplification factor
#: ``R(z)``, ``z = -dt lambda``: Euler ``R = 1 + z``; every two-stage second-order scheme
#: ``R = 1 + z + z^2 / 2 = ((1 + z)^2 + 1) / 2``, which lies in ``[1/2, 1]`` exactly for
#: ``z in [-2, 0]``. Both give ``c = 2``.
STABILITY_INTERVAL = {"euler": 2.0, "heun": 2.0, "midpoint": 2.0}


def check_scheme(scheme):
    """``scheme`` if it names a time scheme, else a ValueError naming the allowed ones."""
    if not isinstance(scheme, str) or scheme not in SCHEMES:
        raise ValueError(f"unknown scheme {scheme!r}; expected one of {sorted(SCHEMES)} "
                         f"(default {DEFAULT_SCHEME!r})")
    return scheme


def stages(scheme):
    """Refits (network evaluations) per time step of ``scheme``: 1 for Euler, 2 otherwise."""
    return 1 if SCHEMES[check_scheme(scheme)] is None else 2


def amplification(z, scheme):
    """The factor ``R(z)`` by which one step of ``scheme`` multiplies an eigenmode of the heat
    equation, ``z = -dt lambda``: ``1 + z`` (Euler), ``1 + z + z^2 / 2`` (Heun, midpoint).

    ``R(z)^n`` is what ``n`` exact steps make of ``exp(n z)``: the time error of a scheme, apart
    from the refits' (docs/flows.md).

    Parameters
    ----------
    z : float or array, ``-dt lambda``
    scheme : {"euler", "heun", "midpoint"}

    Returns
    -------
    float array shaped like ``z``

    Examples
    --------
    >>> z = -0.1                                   # dt lambda = 0.1; exp(-0.1) = 0.904837
    >>> float(amplification(z, "euler")), float(amplification(z, "heun"))
    (0.9, 0.905)
    """
    z = np.asarray(z, dtype=np.float64)
    return 1.0 + z if stages(scheme) == 1 else 1.0 + z + 0.5 * z * z


def stability_limit(area, n_points, scheme="euler"):
    """Largest stable explicit time step ``dt_max = c h^2 / (4 pi)``, ``h^2 = A / N``.

    A step of ``scheme`` multiplies an eigenmode of eigenvalue ``lambda`` by ``R(-dt lambda)``
    (:func:`amplification`), bounded by 1 for ``dt lambda <= c``, with ``c = 2`` for all three
    schemes: Euler ``|1 + z| <= 1`` and Heun / midpoint ``|1 + z + z^2 / 2| <= 1`` both hold
    exactly on ``z in [-2, 0]``. ``N`` sample values carry at most about ``N`` modes, and by
    Weyl's law the ``N``-th eigenvalue of a surface of area ``A`` is
    ``lambda_N ~ 4 pi N / A``. Hence ``dt <= 2 / lambda_N = A / (2 pi N) = h^2 / (2 pi)``
    with ``h = sqrt(A / N)`` the mean sample spacing (docs/flows.md).

    Parameters
    ----------
    area : float, surface area ``A``
    n_points : int, sample points ``N``
    scheme : {"euler", "heun", "midpoint"}, the time scheme (the limit is the same for all)

    Examples
    --------
    >>> round(stability_limit(4 * np.pi, 1000), 6)           # unit sphere, 1000 sample points
    0.002
    >>> stability_limit(4 * np.pi, 1000, "heun") == stability_limit(4 * np.pi, 1000, "euler")
    True
    """
    c = STABILITY_INTERVAL[check_scheme(scheme)]
    return c * float(area) / (4.0 * math.pi * int(n_points))


def check_stability(dt, area, n_points, mode, what, during="", scheme="euler"):
    """Warn (``mode="warn"``), refuse (``"raise"``) or pass (``"ignore"``) when ``dt`` exceeds
    :func:`stability_limit` of ``scheme``; returns the limit."""
    check_choice(mode, "stability", STABILITY_MODES)
    limit = stability_limit(area, n_points, scheme)
    if dt > limit and mode != "ignore":
        c = STABILITY_INTERVAL[scheme]
        msg = (f"{what}: time step dt = {dt:.4g} exceeds the explicit stability limit "
               f"dt <= h^2 / (2 pi) = A / (2 pi N) = {limit:.4g}{during} (scheme {scheme!r}, "
               f"stable for dt lambda <= {c:g}; area A = {area:.4g}, N = {n_points} sample "
               f"points, spacing h = {math.sqrt(area / n_points):.3g}); modes with eigenvalue "
               f"above {c:g} / dt = {c / dt:.4g} can grow. Use a smaller dt or fewer points")
        if mode == "raise":
            raise ValueError(msg)
        warnings.warn(msg, StabilityWarning, stacklevel=3)
    return limit


def default_points(area, dt, lo=64, hi=10242):
    """Sample count meeting the stability limit, clipped to ``[lo, hi]`` (10,242: the paper's)."""
    return int(min(hi, max(lo, math.floor(area / (2.0 * math.pi * dt)))))


def atomic_folder(out, write, overwrite=False):
    """Write a folder through a temporary sibling and rename it into place.

    ``write(tmp_path)`` fills the folder; on any error the temporary folder is removed, so
    ``out`` is either absent, untouched or complete. An existing non-empty ``out`` is refused
    unless ``overwrite``. Every file is fsynced before the rename, and the folder gets the
    permissions of the user's umask (:func:`sns_np._atomic.write_folder`).
    """
    return write_folder(out, write, overwrite)
