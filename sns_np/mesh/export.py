"""Writing meshes with per-vertex fields (PLY, VTU, OBJ, OFF, STL) through meshio, atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from ..errors import ShapeError

__all__ = ["write_mesh", "WRITE_FORMATS"]

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

    The file is written to a temporary name in the same folder and renamed into place, so an
    error never leaves a half-written file.

    Returns
    -------
    Path of the written file.
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
            names = (["nx", "ny", "nz"] if name == "normal" and arr.shape[1] == 3 else
                     [f"{name}_{c}" for c in "xyz"[:arr.shape[1]]] if arr.shape[1] <= 3 else
                     [f"{name}_{i}" for i in range(arr.shape[1])])
            for i, nm in enumerate(names):
                data[nm] = np.ascontiguousarray(arr[:, i])
        else:
            data[name] = arr
    if data and ext not in FIELD_FORMATS:
        raise ValueError(f"{ext} files cannot store per-vertex fields ({', '.join(data)}); "
                         f"write .ply or .vtu, or pass no fields")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise OSError(f"directory {str(directory)!r} does not exist")
    # meshio warns on stderr when it casts int64 faces down for PLY; PLY takes int32 anyway
    cells = F.astype(np.int32 if ext == ".ply" and len(V) < 2**31 else np.int64)
    mesh = meshio.Mesh(V, [("triangle", cells)], point_data=data)
    fd, tmp = tempfile.mkstemp(prefix=path.stem + ".", suffix=".tmp" + ext, dir=directory)
    os.close(fd)
    try:
        kwargs = {"binary": binary} if ext == ".ply" else {}
        meshio.write(tmp, mesh, file_format=WRITE_FORMATS[ext], **kwargs)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
