"""Input checks shared by the public functions (private module).

Jitted kernels never validate; the thin Python layer in front of them calls these helpers so
that every bad input fails early with a message naming what was received and what was expected.
"""

from __future__ import annotations

import numbers

import numpy as np

from .errors import ShapeError

#: default tolerance on | |p| - 1 | for points said to lie on the unit sphere
SPHERE_TOL = 1e-6


def as_generator(rng) -> np.random.Generator:
    """Return a ``numpy.random.Generator`` from ``None``, an int seed or a Generator.

    ``None`` gives a generator seeded with 0, so that results are reproducible by default.
    """
    if rng is None:
        return np.random.default_rng(0)
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, numbers.Integral) and not isinstance(rng, bool):
        if int(rng) < 0:
            raise ValueError(f"rng seed must be a non-negative integer, got {rng}")
        return np.random.default_rng(int(rng))
    raise TypeError(
        f"rng must be None, a non-negative int seed or a numpy.random.Generator, "
        f"got {type(rng).__name__}"
    )


def as_float_array(a, name: str, dtype=np.float64, *,
                   allow_int: bool = True) -> np.ndarray:
    """Convert ``a`` to a floating array of ``dtype``; reject complex, object and bool data."""
    arr = np.asarray(a)
    if arr.dtype == object or np.iscomplexobj(arr) or arr.dtype == bool:
        raise ShapeError(f"{name} must be a real floating array, got dtype {arr.dtype}")
    if not allow_int and not np.issubdtype(arr.dtype, np.floating):
        raise ShapeError(f"{name} must be a floating array, got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=dtype)


def check_finite(a: np.ndarray, name: str) -> None:
    """Raise :class:`ShapeError` naming the first non-finite entry of ``a``."""
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ShapeError(
            f"{name} contains non-finite values (first at index {tuple(int(i) for i in bad)}: "
            f"{a[tuple(bad)]}); expected finite numbers"
        )


def as_points(x, name: str = "x", dim: int = 3, dtype=np.float64) -> np.ndarray:
    """Validate an (n, dim) array of finite points; one point (dim,) becomes (1, dim)."""
    arr = as_float_array(x, name, dtype=dtype)
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ShapeError(f"{name} must have shape (n, {dim}), got {np.shape(x)}")
    check_finite(arr, name)
    return arr


def as_sphere_points(p, name: str = "p", tol: float = SPHERE_TOL) -> np.ndarray:
    """Validate (n, 3) float64 points on the unit sphere, | |p| - 1 | <= tol.

    Points within the tolerance are returned as given (not renormalised), so that callers see
    exactly the points they passed.
    """
    arr = as_points(p, name)
    r = np.linalg.norm(arr, axis=1)
    off = np.abs(r - 1.0)
    if off.size and off.max() > tol:
        k = int(np.argmax(off))
        raise ShapeError(
            f"{name} must lie on the unit sphere (| |p| - 1 | <= {tol:g}); point {k} has "
            f"|p| = {r[k]:.12g}. Normalise with p / np.linalg.norm(p, axis=1, keepdims=True)."
        )
    return arr


def check_order(order, allowed=(0, 1, 2)) -> int:
    """Validate a derivative order."""
    if isinstance(order, bool) or not isinstance(order, numbers.Integral) or order not in allowed:
        raise ValueError(f"order must be one of {tuple(allowed)}, got {order!r}")
    return int(order)


def check_choice(value, name: str, choices) -> str:
    """Validate a string option against its allowed values."""
    if value not in choices:
        raise ValueError(f"unknown {name} {value!r}; expected one of {sorted(choices)}")
    return value


def check_positive_int(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_positive_float(value, name: str, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value!r}")
    return v


def check_output_file(path, suffix: str, what: str = "output", hint: str = ""):
    """A file name to be written later: ``suffix`` in any case, in an existing folder; checked
    before the work that produces it starts. Returns a :class:`~pathlib.Path`."""
    from pathlib import Path
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise ValueError(f"{what} {path.name!r} must end in {suffix}{hint}")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"{what} folder {str(folder)!r} does not exist")
    return path
