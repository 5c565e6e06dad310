"""Writing meshes with per-vertex fields (PLY, VTU, OBJ, OFF, STL) through meshio, atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._atomic import write_file
from ..errors import ShapeError

__all__ = ["write_mesh", "written_field_names", "WRITE_FORMATS"]

#: file extension -> meshio format name
WRITE_FORMATS = {".ply": "ply", ".vtu": "vtu", ".obj": "obj", ".off": "off", ".stl": "stl"}
#: formats that keep per-vertex fields
FIELD_FORMATS = {".ply", ".vtu"}


def write_mesh(path, V, F, point_data=None, binary=True):
    """Write a triangle mesh and per-vertex fields.

    Parameters
    ----------
    path : str or Path, ending in .ply, .vtu, .obj, .off or .stl
    V : (n, 3) float array
    F : (m, 3) int array
    point_data : dict name -> (n,) or (n, 3) array, optional
        Per-vertex fields. PLY stores each component as its own vertex property (a vector
        field ``v`` becomes ``v_x, v_y, v_z``; ``normal`` becomes ``nx, ny, nz``, which MeshLab
        shows as normals); VTU keeps vectors as vectors (ParaView). OBJ, OFF and STL keep only
        the geometry: passing fields to them raises, so nothing is silently dropped.
    binary : bool, PLY only

    The file is written to a temporary name in the same folder, flushed to disk and renamed
    into place, so an error or a crash never leaves a half-written file; it gets the
    permissions of any new file under the user's umask.

    Returns
    -------
    Path of the written file.

    See Also
    --------
    written_field_names : the property names a file gets for given fields

    Examples
    --------
    >>> from sns_np.mesh import icosphere, write_mesh
    >>> V, F = icosphere(1)
    >>> write_mesh("sphere.ply", V, F, {"height": V[:, 2]}).name    # in the current folder
    'sphere.ply'
    """
    import meshio

    path = Path(path)
    ext = path.suffix.lower()
    if ext not in WRITE_FORMATS:
        raise ValueError(f"cannot write {path.name!r}: unsupported extension {ext!r}; expected "
                         f"one of {sorted(WRITE_FORMATS)}")
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ShapeError(f"V must have shape (n, 3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer):
        raise ShapeError(f"F must be an integer array of shape (m, 3), got {F.shape} {F.dtype}")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise ShapeError(f"F refers to vertices outside 0..{len(V) - 1}")
    data = {}
    for name, arr in (point_data or {}).items():
        arr = np.asarray(arr, dtype=np.float64)
        if arr.shape[0] != len(V) or arr.ndim not in (1, 2):
            raise ShapeError(f"point field {name!r} has shape {arr.shape}; expected ({len(V)},) "
                             f"or ({len(V)}, k)")
        if ext == ".ply" and arr.ndim == 2:
            for i, nm in enumerate(_property_names(ext, name, arr.shape)):
                data[nm] = np.ascontiguousarray(arr[:, i])
        else:
            data[name] = arr
    if data and ext not in FIELD_FORMATS:
        raise ValueError(f"{ext} files cannot store per-vertex fields ({', '.join(data)}); "
                         f"write .ply or .vtu, or pass no fields")
    # meshio warns on stderr when it casts int64 faces down for PLY; PLY takes int32 anyway
    cells = F.astype(np.int32 if ext == ".ply" and len(V) < 2**31 else np.int64)
    mesh = meshio.Mesh(V, [("triangle", cells)], point_data=data)
    kwargs = {"binary": binary} if ext == ".ply" else {}
    # a temporary file with the umask's permissions, fsynced, then renamed (sns_np/_atomic.py)
    return write_file(path, lambda tmp: meshio.write(tmp, mesh, file_format=WRITE_FORMATS[ext],
                                                     **kwargs))


def _property_names(ext, name, shape):
    """The names under which a field of this shape is stored in a file of extension ext."""
    if ext != ".ply" or len(shape) == 1:
        return [name]
    k = shape[1]
    if name == "normal" and k == 3:
        return ["nx", "ny", "nz"]
    return [f"{name}_{c}" for c in "xyz"[:k]] if k <= 3 else [f"{name}_{i}" for i in range(k)]


def written_field_names(path, point_data) -> list:
    """The per-vertex property names that :func:`write_mesh` writes for ``point_data``.

    PLY has scalar properties only, so vector fields are split (``normal`` into ``nx, ny,
    nz``, any other ``v`` into ``v_x, v_y, v_z``); VTU keeps each field under its own name;
    OBJ, OFF and STL keep none.

    Parameters
    ----------
    path : str or Path, the output file (only its extension matters)
    point_data : dict name -> (n,) or (n, k) array

    Returns
    -------
    list of str, in the order they are written

    Examples
    --------
    >>> import numpy as np
    >>> fields = {"normal": np.zeros((4, 3)), "H": np.zeros(4), "dmin": np.zeros((4, 3))}
    >>> written_field_names("out.ply", fields)
    ['nx', 'ny', 'nz', 'H', 'dmin_x', 'dmin_y', 'dmin_z']
    >>> written_field_names("out.vtu", fields)
    ['normal', 'H', 'dmin']
    """
    ext = Path(path).suffix.lower()
    if ext not in FIELD_FORMATS:
        return []
    return [nm for name, arr in (point_data or {}).items()
            for nm in _property_names(ext, name, np.shape(arr))]
