"""The file format of a :class:`~sns_np.nn.mlp.ResidualMLP` (private).

A network is stored as a handful of named arrays (docs/model_files.md)::

    format            "sns_np.ResidualMLP"
    format_version    1
    in_dim, out_dim, width, depth     integers
    bias              bool
    dtype             "float32" or "float64"
    theta             (n_params,) the packed parameters, in that dtype

with an optional ``prefix`` on every name, so that a surface or a field can store its network
among its own arrays. Reading checks every field, and compares the parameter count implied by
the architecture with the declared shape of ``theta`` before anything of that size is
allocated (:mod:`sns_np._npz`). The methods ``state``, ``from_state``, ``save`` and ``load`` of
``ResidualMLP`` call these functions.
"""

from __future__ import annotations

import numpy as np

from .. import _npz
from ..errors import ModelFileError

FORMAT = "sns_np.ResidualMLP"
FORMAT_VERSION = 1


def state(net, prefix=""):
    """The arrays that describe ``net`` (architecture, dtype, format, parameters)."""
    a = net.architecture()
    return {
        f"{prefix}format": np.array(FORMAT),
        f"{prefix}format_version": np.array(FORMAT_VERSION),
        f"{prefix}in_dim": np.array(a["in_dim"]), f"{prefix}out_dim": np.array(a["out_dim"]),
        f"{prefix}width": np.array(a["width"]), f"{prefix}depth": np.array(a["depth"]),
        f"{prefix}bias": np.array(a["bias"]), f"{prefix}dtype": np.array(net.dtype.name),
        f"{prefix}theta": net.theta,
    }


def from_state(cls, data, prefix="", source="state"):
    """A new ``cls`` network from :func:`state` arrays (a dict, or an open file), checked."""
    if prefix + "format" not in data:
        raise ModelFileError(f"{source}: missing field {prefix + 'format'!r}; not a "
                             f"{FORMAT} file")
    fmt = _npz.field(data, prefix + "format", source, kinds="U", what="text")
    if fmt != FORMAT:
        raise ModelFileError(f"{source}: format is {fmt!r}, expected {FORMAT!r}")
    version = _npz.int_field(data, prefix + "format_version", source)
    if version != FORMAT_VERSION:
        raise ModelFileError(f"{source}: format version {version} is not supported "
                             f"(this sns_np reads version {FORMAT_VERSION})")
    arch = {k: _npz.int_field(data, prefix + k, source, minimum=0 if k == "depth" else 1)
            for k in ("in_dim", "out_dim", "width", "depth")}
    bias = _npz.field(data, prefix + "bias", source, kinds="b", what="True or False")
    name = _npz.field(data, prefix + "dtype", source, kinds="U", what="a dtype name")
    if name not in ("float32", "float64"):
        raise ModelFileError(f"{source}: field {prefix + 'dtype'!r} must be 'float32' or "
                             f"'float64', got {name[:40]!r}")
    dtype = np.dtype(name)
    n = cls.count_params(**arch, bias=bias)
    key = prefix + "theta"
    if key not in data:
        raise ModelFileError(f"{source}: missing field {key!r}")
    shape, dt = _npz.declared(data, key)
    if shape != (n,) or dt != dtype:
        raise ModelFileError(
            f"{source}: field {key!r} (the parameter vector) has shape {shape} and dtype "
            f"{dt}; the stored architecture ({arch['width']} wide, {arch['depth']} blocks) "
            f"needs ({n},) {dtype}")
    net = cls.zeros(**arch, bias=bias, dtype=dtype)
    if isinstance(data, _npz.NpzReader):
        data.read_into(key, net.theta)
    else:
        net.theta[...] = data[key]
    if not np.all(np.isfinite(net.theta)):
        raise ModelFileError(f"{source}: field {key!r} contains non-finite values")
    return net


def save(net, path):
    """Write ``net`` to ``path`` (.npz, no pickles), atomically; the path written."""
    return _npz.save_npz(path, state(net))


def load(cls, path):
    """Read a network written by :func:`save`, never unpickling."""
    try:
        with _npz.load_npz(path) as data:
            return from_state(cls, data, source=str(path))
    except (RecursionError, MemoryError) as exc:   # a last line of defence: one line
        raise ModelFileError(f"{path}: cannot be read ({type(exc).__name__})") from None
