"""The SphericalNeuralSurface: a residual network plus its output transform.

    S(p) = c + s * net(p)

``net`` is a :class:`~sns_np.nn.ResidualMLP` fitted in a normalised frame (the surface centred
at the origin and scaled to area 4 pi, as in the paper); the centre ``c`` and scale ``s`` map
its output back to the units of the input mesh, so positions, curvatures and areas are reported
in those units. The object is a surface map (DESIGN.md): ``jet(p, order)`` with ambient
derivatives, plus the directional jets that geometry code uses to propagate 7 streams instead
of 10.
"""

from __future__ import annotations

import json

import numpy as np

from .. import _npz
from .._npz import load_npz, save_npz
from .._validation import as_points, check_order
from ..errors import ModelFileError
from ..nn.mlp import ResidualMLP
from ..nn.optim import optimizer_class

__all__ = ["SphericalNeuralSurface"]

FORMAT = "sns_np.SphericalNeuralSurface"
FORMAT_VERSION = 1


class SphericalNeuralSurface:
    """A genus-0 surface encoded by a network restricted to the unit sphere.

    Parameters
    ----------
    net : ResidualMLP with in_dim = out_dim = 3
    center : (3,) float array, the output translation c
    scale : float, the output scale s > 0
    metadata : dict, optional
        JSON-serialisable information kept with the model (source, fit options, report).

    Examples
    --------
    >>> import numpy as np
    >>> from sns_np.nn import ResidualMLP
    >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0)
    >>> y, J = S.jet(np.array([[0.0, 0.0, 1.0]]), 1)
    >>> J.shape
    (1, 3, 3)

    Fitting, the usual way to make one::

        S = SphericalNeuralSurface.fit(V, F)          # a closed genus-0 mesh
        S = SphericalNeuralSurface.fit_shape(shape)   # an analytic surface map
    """

    def __init__(self, net: ResidualMLP, center=(0.0, 0.0, 0.0), scale=1.0, metadata=None):
        if not isinstance(net, ResidualMLP):
            raise TypeError(f"net must be a ResidualMLP, got {type(net).__name__}")
        if net.in_dim != 3 or net.out_dim != 3:
            raise ValueError(f"a surface network maps R^3 -> R^3; got in_dim={net.in_dim}, "
                             f"out_dim={net.out_dim}")
        center = np.asarray(center, dtype=np.float64)
        if center.shape != (3,) or not np.all(np.isfinite(center)):
            raise ValueError(f"center must be 3 finite numbers, got {center!r}")
        scale = float(scale)
        if not np.isfinite(scale) or scale <= 0:
            raise ValueError(f"scale must be finite and > 0, got {scale}")
        self.net = net
        self.center = center
        self.scale = scale
        self.metadata = dict(metadata or {})

    # ------------------------------------------------------------------ the surface map
    def jet(self, p, order=0, directions=None, second=None):
        """Value and ambient derivatives of S = c + s net, in the input's units.

        Parameters and returns as :meth:`ResidualMLP.jet` (surface-map protocol), in float64.

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0)
        >>> p = np.array([[0.0, 0.0, 1.0]])
        >>> y, J = S.jet(p, 1)
        >>> bool(np.allclose(y, 2.0 * S.net(p))), bool(np.allclose(J, 2.0 * S.net.jet(p, 1)[1]))
        (True, True)
        """
        order = check_order(order)
        p = as_points(p, "p")
        out = self.net.jet(p, order, directions=directions, second=second)
        if order == 0:
            return self.center + self.scale * out.astype(np.float64, copy=False)
        y = self.center + self.scale * out[0].astype(np.float64, copy=False)
        rest = tuple(self.scale * a.astype(np.float64, copy=False) for a in out[1:])
        return (y,) + rest

    def __call__(self, p):
        """Surface points S(p) (n, 3) for sphere points p (n, 3)."""
        return self.jet(p, 0)

    @property
    def n_params(self) -> int:
        return self.net.n_params

    def __repr__(self):
        src = self.metadata.get("source", "")
        src = f", source={src!r}" if src else ""
        return (f"SphericalNeuralSurface(width={self.net.width}, depth={self.net.depth}, "
                f"scale={self.scale:.6g}{src})")

    # ------------------------------------------------------------------ construction
    @classmethod
    def fit(cls, V, F, **options):
        """Fit a surface to a closed genus-0 triangle mesh; see :func:`sns_np.surface.fit_mesh`.

        Examples
        --------
        >>> from sns_np.shapes import Ellipsoid
        >>> V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(2)
        >>> S, report = SphericalNeuralSurface.fit(V, F, width=16, depth=1, steps=30, batch=256,
        ...                                        progress=False)
        >>> S.n_params, report.steps
        (608, 30)
        """
        from .fit import fit_mesh
        return fit_mesh(V, F, **options)

    @classmethod
    def fit_shape(cls, shape, **options):
        """Fit a surface to an analytic surface map; see :func:`sns_np.surface.fit_shape`.

        Examples
        --------
        >>> from sns_np.shapes import Sphere
        >>> S, report = SphericalNeuralSurface.fit_shape(Sphere(2.0), width=16, depth=1, steps=200,
        ...                                              batch=256, progress=False)
        >>> r = np.linalg.norm(S(np.array([[0.0, 0.0, 1.0]])), axis=1)
        >>> bool(abs(r[0] - 2.0) < 0.1)
        True
        """
        from .fit import fit_shape
        return fit_shape(shape, **options)

    @classmethod
    def fit_sdf(cls, sdf, **options):
        """Fit a surface to the zero set of a signed distance function (:mod:`sns_np.surface.sdf`).

        Examples
        --------
        >>> S, report = SphericalNeuralSurface.fit_sdf(lambda x: np.linalg.norm(x, axis=1) - 1.0,
        ...                                            width=16, depth=1, steps=60, iterations=1,
        ...                                            n_eval=512, progress=False)
        >>> bool(report.relative_mean < 0.02)
        True
        """
        from .sdf import fit_sdf
        return fit_sdf(sdf, **options)

    # ------------------------------------------------------------------ output
    def to_mesh(self, level: int = 5, fields: bool = True, progress: bool = False):
        """Evaluate the surface on an icosphere.

        Parameters
        ----------
        level : int, icosphere subdivision level (level 5: 10,242 vertices; 6: 40,962)
        fields : bool, also compute per-vertex differential quantities
        progress : bool, show a progress bar on stderr (the vertices in chunks)

        Returns
        -------
        V : (n, 3) float array, surface points S(p) at the icosphere vertices p
        F : (m, 3) int array, faces (oriented outward when S preserves orientation)
        data : dict of per-vertex arrays: ``sphere`` (n, 3) and, with ``fields``, ``normal``
            (n, 3), ``H``, ``K``, ``kmin``, ``kmax``, ``area_element`` (n,), ``dmin``, ``dmax``
            (n, 3)

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0))
        >>> V, F, data = S.to_mesh(level=1)
        >>> V.shape, F.shape, sorted(data)[:4]
        ((42, 3), (80, 3), ['H', 'K', 'area_element', 'dmax'])
        """
        from .._progress import Progress
        from ..mesh import icosphere
        P, F = icosphere(level)
        data = {"sphere": P}
        if not fields:
            return self.jet(P, 0), F, data
        from ..geometry import differential_quantities
        names = ("normal", "H", "K", "kmin", "kmax", "area_element", "dmin", "dmax")
        attrs = ("n", "H", "K", "kmin", "kmax", "area_element", "dmin", "dmax")
        parts = {name: [] for name in ("x",) + names}
        step = 8192
        bar = Progress(len(P), "eval", enabled=progress)
        for lo in range(0, len(P), step):
            dq = differential_quantities(self, P[lo:lo + step], on_degenerate="nan")
            parts["x"].append(dq.x)
            for name, attr in zip(names, attrs):
                parts[name].append(getattr(dq, attr))
            if lo + step < len(P):
                bar.update(lo + step)
        bar.close(len(P))
        data.update({name: np.concatenate(parts[name]) for name in names})
        return np.concatenate(parts["x"]), F, data

    # ------------------------------------------------------------------ files
    def state(self) -> dict:
        """The arrays that describe the surface: format, version, centre, scale, metadata (JSON) and
        the network's :meth:`~sns_np.nn.ResidualMLP.state` under ``net.``.

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0)
        >>> state = S.state()
        >>> str(state["format"]), float(state["scale"]), state["net.theta"].shape
        ('sns_np.SphericalNeuralSurface', 2.0, (176,))
        """
        out = {
            "format": np.array(FORMAT), "format_version": np.array(FORMAT_VERSION),
            "center": self.center, "scale": np.array(self.scale),
            "metadata": np.array(json.dumps(self.metadata, default=_json_default)),
        }
        out.update(self.net.state(prefix="net."))
        return out

    @classmethod
    def from_state(cls, data, source="state"):
        """Rebuild a surface from :meth:`state` arrays (or an open file), checking every field;
        any problem is a :class:`ModelFileError` naming ``source`` and the field.

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0)
        >>> again = SphericalNeuralSurface.from_state(S.state())
        >>> again.scale, bool(np.array_equal(again.net.theta, S.net.theta))
        (2.0, True)
        >>> state = S.state()
        >>> state["scale"] = np.array(-1.0)
        >>> SphericalNeuralSurface.from_state(state, source="crafted.npz")
        Traceback (most recent call last):
            ...
        sns_np.errors.ModelFileError: crafted.npz: invalid transform or metadata (scale ...
        """
        if "format" not in data:
            raise ModelFileError(f"{source}: missing field 'format'; not an sns_np model file")
        fmt = _npz.field(data, "format", source, kinds="U", what="text")
        if fmt != FORMAT:
            hint = " (a bare network: use ResidualMLP.load)" if fmt == "sns_np.ResidualMLP" else ""
            raise ModelFileError(f"{source}: format is {fmt[:80]!r}, expected {FORMAT!r}{hint}")
        version = _npz.int_field(data, "format_version", source)
        if version != FORMAT_VERSION:
            raise ModelFileError(f"{source}: model format version {version} is not supported "
                                 f"(this sns_np reads version {FORMAT_VERSION})")
        center = _npz.field(data, "center", source, kinds="fiu", shape=(3,), what="3 numbers")
        scale = _npz.field(data, "scale", source, kinds="fiu", what="a number")
        metadata = _npz.json_field(data, "metadata", source)
        _check_metadata(metadata, source)
        net = ResidualMLP.from_state(data, prefix="net.", source=source)
        if "checkpoint.key" in data:
            _check_checkpoint(data, source, net.theta.size)
        try:
            return cls(net, center=np.asarray(center, dtype=np.float64), scale=float(scale),
                       metadata=metadata)
        except (ValueError, TypeError) as exc:
            raise ModelFileError(f"{source}: invalid transform or metadata ({exc})") from None

    def save(self, path):
        """Write the model to ``path`` (.npz, no pickles), atomically.

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0)
        >>> S.metadata["source"] = "example"
        >>> S.save("surface.npz").name
        'surface.npz'
        >>> SphericalNeuralSurface.load("surface.npz").metadata
        {'source': 'example'}
        """
        return save_npz(path, self.state())

    @classmethod
    def load(cls, path) -> SphericalNeuralSurface:
        """Read a model written by :meth:`save` (or a fit checkpoint); never unpickles.

        The cost of refusing a crafted file is bounded (sns_np/_npz.py): sizes are checked
        before anything is allocated. Every problem is a :class:`ModelFileError` naming the
        file and the field.

        Examples
        --------
        >>> from sns_np.nn import ResidualMLP
        >>> S = SphericalNeuralSurface(ResidualMLP(width=8, depth=1, seed=0), scale=2.0)
        >>> path = S.save("surface.npz")
        >>> SphericalNeuralSurface.load(path)
        SphericalNeuralSurface(width=8, depth=1, scale=2)
        >>> with open("broken.npz", "wb") as fh:
        ...     _ = fh.write(b"not a zip archive")
        >>> SphericalNeuralSurface.load("broken.npz")
        Traceback (most recent call last):
            ...
        sns_np.errors.ModelFileError: broken.npz: not a readable .npz model file (not a zip archive)
        """
        try:
            with load_npz(path) as data:
                return cls.from_state(data, source=str(path))
        except (RecursionError, MemoryError) as exc:   # a last line of defence: one line
            raise ModelFileError(f"{path}: cannot be read ({type(exc).__name__})") from None


#: fit-report entries that readers (``sns-np info``) format as numbers
_FIT_NUMBERS = ("steps", "seconds", "position_mean", "position_relative", "normal_mean_deg")


def _check_metadata(metadata, source):
    """The metadata must be a JSON object; a ``fit`` block must hold its numbers as numbers."""
    if not isinstance(metadata, dict):
        raise ModelFileError(f"{source}: field 'metadata' must be a JSON object, got "
                             f"{type(metadata).__name__}")
    fit = metadata.get("fit")
    if fit is None:
        return
    if not isinstance(fit, dict):
        raise ModelFileError(f"{source}: field 'metadata.fit' must be a JSON object, got "
                             f"{type(fit).__name__}")
    for k in _FIT_NUMBERS:
        v = fit.get(k)
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise ModelFileError(f"{source}: field 'metadata.fit.{k}' must be a number, got "
                                 f"{type(v).__name__}")
    for k in ("options", "history", "choices"):
        if not isinstance(fit.get(k, {}), dict):
            raise ModelFileError(f"{source}: field 'metadata.fit.{k}' must be a JSON object, "
                                 f"got {type(fit[k]).__name__}")


def _check_checkpoint(data, source, n_theta):
    """The fields that resuming a fit reads, checked before it reads them (a crafted random
    generator state would otherwise surface as a TypeError deep inside NumPy)."""
    _npz.field(data, "checkpoint.key", source, kinds="U", what="text")
    _npz.int_field(data, "checkpoint.step", source, minimum=0)
    seconds = _npz.field(data, "checkpoint.seconds", source, kinds="fiu", what="a number")
    if not np.isfinite(seconds) or seconds < 0:
        raise ModelFileError(f"{source}: field 'checkpoint.seconds' must be finite and >= 0")
    state = _npz.json_field(data, "checkpoint.rng", source)
    names = ("PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64")
    name = state.get("bit_generator") if isinstance(state, dict) else None
    if name not in names:
        raise ModelFileError(f"{source}: field 'checkpoint.rng' is not a random generator "
                             f"state (bit_generator must be one of {', '.join(names)})")
    try:
        getattr(np.random, name)().state = state
    except Exception as exc:  # TypeError, ValueError, KeyError, OverflowError...
        raise ModelFileError(f"{source}: field 'checkpoint.rng' is not a valid {name} state "
                             f"({type(exc).__name__})") from None
    fields = data.files if hasattr(data, "files") else list(data)
    for k in fields:
        if k.startswith("checkpoint.history."):
            shape, dt = _npz.declared(data, k)
            if len(shape) != 1 or dt.kind not in "fiu":
                raise ModelFileError(f"{source}: field {k!r} must be a vector of numbers, "
                                     f"got {dt} of shape {shape}")
    if "opt.t" in data:
        _npz.int_field(data, "opt.t", source, minimum=0)
    layout = {k[4:]: _npz.declared(data, k) for k in fields
              if k.startswith("opt.") and k not in ("opt.kind", "opt.t")}
    if layout and "opt.kind" not in data:
        raise ModelFileError(f"{source}: optimiser state without field 'opt.kind'")
    if "opt.kind" in data:
        kind = _npz.field(data, "opt.kind", source, kinds="U", what="text")
        try:
            cls = optimizer_class(kind[:80])
        except ValueError as exc:
            raise ModelFileError(f"{source}: field 'opt.kind': {exc}") from None
        if cls.__name__ != kind:
            raise ModelFileError(f"{source}: field 'opt.kind' is {kind!r}, expected the "
                                 f"class name {cls.__name__!r}")
        try:
            cls.check_state_layout(layout, n_theta, prefix="opt.")
        except ValueError as exc:
            raise ModelFileError(f"{source}: {exc}") from None


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)
