"""Reading surface meshes from OBJ, OFF, PLY and STL files.

OBJ and OFF are parsed here (only positions and face corners are read, so texture coordinates
and normals can neither split vertices nor break the reader); PLY and STL go through meshio,
with trimesh as a fallback. Polygons are triangulated, vertices duplicated along seams are
merged, unreferenced vertices are dropped, and a :class:`LoadReport` records every change.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._arrays import unique_edges
from .errors import MeshFileError

__all__ = ["LoadReport", "load", "SUPPORTED_FORMATS"]

SUPPORTED_FORMATS = (".obj", ".off", ".ply", ".stl")


@dataclass(frozen=True)
class LoadReport:
    """What :func:`load` read and what it changed.

    Attributes
    ----------
    path : str
    n_vertices_read, n_faces_read : int
        Vertex positions and faces (of any size) as stored in the file.
    n_polygons_triangulated : int
        Faces with more than three corners, each split into ``k - 2`` triangles.
    n_vertices_merged : int
        Vertices removed by merging exactly coincident positions.
    n_degenerate_faces_dropped : int
        Faces that repeated a vertex after merging (and were removed).
    n_unreferenced_dropped : int
        Vertices used by no face (removed; the remaining ones keep their order).
    n_vertices, n_faces : int
        Size of the returned mesh.
    """

    path: str
    n_vertices_read: int
    n_faces_read: int
    n_polygons_triangulated: int
    n_vertices_merged: int
    n_degenerate_faces_dropped: int
    n_unreferenced_dropped: int
    n_vertices: int
    n_faces: int

    @property
    def changed(self) -> bool:
        """True when the returned mesh differs from the file's own vertex and face lists."""
        return bool(self.n_polygons_triangulated or self.n_vertices_merged
                    or self.n_degenerate_faces_dropped or self.n_unreferenced_dropped)


def _read_obj(path):
    vs, polys = [], []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "v":
                if len(parts) < 4:
                    raise MeshFileError(f"{path}: line {lineno}: a 'v' line needs x y z, "
                                        f"got {line.strip()!r}")
                vs.append(parts[1:4])
            elif tag == "f":
                # a corner is v, v/vt, v//vn or v/vt/vn; only the position index matters
                try:
                    idx = [int(t.split("/", 1)[0]) for t in parts[1:]]
                except ValueError:
                    raise MeshFileError(f"{path}: line {lineno}: cannot parse face "
                                        f"{line.strip()!r}") from None
                nv = len(vs)
                # OBJ indices are 1-based; negative ones count back from the latest vertex
                polys.append([i - 1 if i > 0 else nv + i for i in idx])
    try:
        V = np.array(vs, dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise MeshFileError(f"{path}: cannot parse vertex coordinates ({exc})") from None
    return V, polys


def _read_off(path):
    with open(path, encoding="utf-8", errors="replace") as fh:
        tokens = [ln.split("#", 1)[0].split() for ln in fh]
    lines = [t for t in tokens if t]
    if not lines or not lines[0][0].endswith("OFF"):
        raise MeshFileError(f"{path}: not an OFF file (the first line must be 'OFF')")
    head = lines[0][1:] if len(lines[0]) > 1 else lines[1]
    body = lines[1:] if len(lines[0]) > 1 else lines[2:]
    try:
        nv, nf = int(head[0]), int(head[1])
        V = np.array([ln[:3] for ln in body[:nv]], dtype=np.float64).reshape(-1, 3)
        polys = []
        for ln in body[nv:nv + nf]:
            k = int(ln[0])
            polys.append([int(t) for t in ln[1:1 + k]])
    except (ValueError, IndexError) as exc:
        raise MeshFileError(f"{path}: malformed OFF data ({exc})") from None
    if V.shape[0] != nv or len(polys) != nf:
        raise MeshFileError(f"{path}: the header announces {nv} vertices and {nf} faces, the "
                            f"file holds {V.shape[0]} and {len(polys)}")
    return V, polys


def _read_meshio_or_trimesh(path):
    errors = []
    try:
        import meshio
    except ImportError:
        errors.append("meshio is not installed")
    else:
        try:
            # meshio prints to stdout/stderr and may call sys.exit on a failed read
            with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), \
                    contextlib.redirect_stderr(io.StringIO()):
                warnings.simplefilter("ignore")
                m = meshio.read(path)
            polys = []
            for block in m.cells:
                if block.type in ("vertex", "line"):
                    continue
                if block.type not in ("triangle", "quad") and not block.type.startswith("polygon"):
                    raise MeshFileError(f"{path}: holds {block.type!r} cells; expected a "
                                        "surface of triangles or polygons")
                polys.extend(np.asarray(block.data, dtype=np.int64).tolist())
            return np.asarray(m.points, dtype=np.float64)[:, :3], polys
        except MeshFileError:
            raise
        except (Exception, SystemExit) as exc:  # meshio raises many types; try trimesh
            errors.append(f"meshio: {type(exc).__name__}: {exc}")
    try:
        import trimesh
    except ImportError:
        errors.append("trimesh is not installed (pip install 'sns-np[meshes]')")
    else:
        try:
            t = trimesh.load(path, process=False, force="mesh")
            return np.asarray(t.vertices, dtype=np.float64), np.asarray(t.faces).tolist()
        except Exception as exc:
            errors.append(f"trimesh: {type(exc).__name__}: {exc}")
    raise MeshFileError(f"cannot read mesh file {path}: " + "; ".join(errors))


def _triangulate(V, polys):
    """Triangles of all faces; a k-gon becomes a fan from the corner maximising the min angle."""
    sizes = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
    if sizes.size and sizes.min() < 3:
        f = int(np.argmax(sizes < 3))
        raise MeshFileError(f"face {f} has {int(sizes[f])} corners; expected at least 3")
    tris, order = [], []
    for k in np.unique(sizes):
        idx = np.flatnonzero(sizes == k)
        P = np.array([polys[i] for i in idx], dtype=np.int64)
        if k == 3:
            tris.append(P)
            order.append(idx)
            continue
        best, best_angle = None, None
        for a in range(k):
            R = np.roll(P, -a, axis=1)
            T = np.stack([np.stack([R[:, 0], R[:, i], R[:, i + 1]], axis=1)
                          for i in range(1, k - 1)], axis=1)          # (p, k-2, 3)
            ang = _min_angle(V, T)
            if best is None:
                best, best_angle = T, ang
            else:
                better = ang > best_angle
                best[better], best_angle[better] = T[better], ang[better]
        tris.append(best.reshape(-1, 3))
        order.append(np.repeat(idx, k - 2))
    F = np.concatenate(tris)
    # keep the file's face order (triangles of one polygon stay together)
    return F[np.argsort(np.concatenate(order), kind="stable")], int((sizes > 3).sum())


def _min_angle(V, T):
    """Smallest corner angle over the triangles of each fan, T (p, t, 3) -> (p,)."""
    P = V[T]
    worst = np.full(T.shape[:2], np.pi)
    for c in range(3):
        u = P[..., (c + 1) % 3, :] - P[..., c, :]
        v = P[..., (c + 2) % 3, :] - P[..., c, :]
        ang = np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("...i,...i", u, v))
        worst = np.minimum(worst, ang)
    return worst.min(axis=1)


def _merge_coincident(V, F):
    _, first, inv = np.unique(V, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    # keep the first occurrence of each position, in file order
    keep = np.sort(first)
    new_id = np.empty(first.size, dtype=np.int64)
    new_id[np.argsort(first)] = np.arange(first.size)
    old_to_new = new_id[inv]
    return V[keep], old_to_new[F], V.shape[0] - keep.size


def _n_boundary_edges(F, n):
    return int((unique_edges(F, n)[2] == 1).sum())


def load(path, *, merge: str | bool = "auto", return_report: bool = False):
    """Read a triangle or polygon surface mesh.

    Parameters
    ----------
    path : str or path-like
        An ``.obj``, ``.off``, ``.ply`` or ``.stl`` file.
    merge : {"auto", True, False}
        Merge vertices with exactly equal positions. ``"auto"`` merges STL files always (they
        store a triangle soup) and other files only when merging closes boundary edges, as for
        vertices duplicated along texture seams; a closed mesh with two coincident but separate
        vertices is left alone.
    return_report : bool
        Also return a :class:`LoadReport`.

    Returns
    -------
    V : (n, 3) float array
    F : (m, 3) int array, the file's winding kept
    report : LoadReport, only when ``return_report`` is true

    Raises
    ------
    MeshFileError
        Missing or unreadable file, unsupported format, non-finite coordinates, out-of-range
        face indices or an empty mesh; the message names the file.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "square_pyramid.obj")
    >>> with open(path, "w") as fh:
    ...     _ = fh.write("v 0 0 0\\nv 1 0 0\\nv 1 1 0\\nv 0 1 0\\nv .5 .5 1\\n"
    ...                  "f 1 4 3 2\\nf 1 2 5\\nf 2 3 5\\nf 3 4 5\\nf 4 1 5\\n")
    >>> V, F, report = load(path, return_report=True)
    >>> F.shape, report.n_polygons_triangulated
    ((6, 3), 1)
    """
    if merge not in ("auto", True, False):
        raise ValueError(f"merge must be 'auto', True or False, got {merge!r}")
    path = Path(path)
    if not path.is_file():
        raise MeshFileError(f"mesh file {str(path)!r} not found" +
                            (" (it is a directory)" if path.is_dir() else ""))
    ext = path.suffix.lower()
    if ext not in SUPPORTED_FORMATS:
        raise MeshFileError(f"{path}: unsupported mesh format {ext!r}; expected one of "
                            f"{', '.join(SUPPORTED_FORMATS)}")
    try:
        if ext == ".obj":
            V, polys = _read_obj(path)
        elif ext == ".off":
            V, polys = _read_off(path)
        else:
            V, polys = _read_meshio_or_trimesh(path)
    except (OSError, UnicodeError) as exc:
        raise MeshFileError(f"cannot read mesh file {path}: {exc}") from None
    n_read, f_read = V.shape[0], len(polys)
    if n_read == 0 or f_read == 0:
        raise MeshFileError(f"{path}: empty mesh ({n_read} vertices, {f_read} faces); expected "
                            "a surface with vertices and faces")
    if not np.all(np.isfinite(V)):
        i = int(np.argwhere(~np.isfinite(V))[0, 0])
        raise MeshFileError(f"{path}: vertex {i} has non-finite coordinates {V[i].tolist()}; "
                            "expected finite numbers")
    lo = min(min(p) for p in polys)
    hi = max(max(p) for p in polys)
    if lo < 0 or hi >= n_read:
        raise MeshFileError(f"{path}: a face refers to vertex {lo if lo < 0 else hi} (0-based) "
                            f"but the file has {n_read} vertices")
    try:
        F, n_poly = _triangulate(V, polys)
    except MeshFileError as exc:
        raise MeshFileError(f"{path}: {exc}") from None

    n_merged = 0
    if merge is True or (merge == "auto" and ext == ".stl"):
        V, F, n_merged = _merge_coincident(V, F)
    elif merge == "auto":
        before = _n_boundary_edges(F, V.shape[0])
        if before:
            Vm, Fm, k = _merge_coincident(V, F)
            if k and _n_boundary_edges(Fm, Vm.shape[0]) < before:
                V, F, n_merged = Vm, Fm, k
    bad = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    n_bad = int(bad.sum()) if n_merged else 0
    if n_bad:
        F = F[~bad]
    used = np.zeros(V.shape[0], dtype=bool)
    used[F.reshape(-1)] = True
    n_unused = int((~used).sum())
    if n_unused:
        remap = np.cumsum(used) - 1
        V, F = V[used], remap[F]
    if F.shape[0] == 0:
        raise MeshFileError(f"{path}: no faces left after removing degenerate ones")
    V, F = np.ascontiguousarray(V), np.ascontiguousarray(F, dtype=np.int64)
    if not return_report:
        return V, F
    report = LoadReport(path=str(path), n_vertices_read=n_read, n_faces_read=f_read,
                        n_polygons_triangulated=n_poly, n_vertices_merged=n_merged,
                        n_degenerate_faces_dropped=n_bad, n_unreferenced_dropped=n_unused,
                        n_vertices=V.shape[0], n_faces=F.shape[0])
    return V, F, report

