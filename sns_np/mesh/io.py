"""Reading surface meshes from OBJ, OFF, PLY and STL files.

OBJ, OFF and PLY are parsed here (only positions and face corners are read, so texture
coordinates and normals can neither split vertices nor break the reader); STL goes through
meshio, with trimesh as a fallback. Polygons are triangulated without folds
(:mod:`._polygons`), vertices duplicated along seams are merged, unreferenced vertices are
dropped, and a :class:`LoadReport` records every change; without ``return_report``, a
:class:`MeshRepairWarning` says what was repaired.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._arrays import unique_edges
from ._ply import read_ply
from ._polygons import triangulate
from .errors import MeshFileError

__all__ = ["LoadReport", "MeshRepairWarning", "load", "SUPPORTED_FORMATS"]

SUPPORTED_FORMATS = (".obj", ".off", ".ply", ".stl")


class MeshRepairWarning(UserWarning):
    """:func:`load` changed the mesh: merged vertices or dropped faces or vertices."""


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
    n_polygons_self_crossing : int
        Polygons that cross or touch themselves in their best-fit plane (or have zero vector
        area): no split of them is free of folded triangles, so they were split as a fan.
    self_crossing_example : str
        Where the first of them is in the file ("path: line 12"), or "".

    Examples
    --------
    >>> import os
    >>> from sns_np.mesh import load
    >>> path = "tetrahedron.obj"                           # in the current folder
    >>> lines = ["v 0 0 0", "v 1 0 0", "v 0 1 0", "v 0 0 1", "v 0 0 1",   # one vertex twice
    ...          "f 1 3 2", "f 1 2 4", "f 1 4 3", "f 2 3 5"]
    >>> with open(path, "w") as fh:
    ...     _ = fh.write(os.linesep.join(lines))
    >>> V, F, report = load(path, return_report=True)
    >>> report.n_vertices_read, report.n_vertices_merged, report.n_vertices, report.n_faces
    (5, 1, 4, 4)
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
    n_polygons_self_crossing: int = 0
    self_crossing_example: str = ""

    def repaired(self, expected_merge: bool = False) -> bool:
        """True when vertices were merged (unless ``expected_merge``), anything was dropped, or
        a self-crossing polygon was split (its triangles may fold).

        Examples
        --------
        >>> from sns_np.mesh.io import LoadReport
        >>> r = LoadReport("m.obj", 5, 4, 0, 1, 0, 0, 4, 4)     # one coincident vertex merged
        >>> r.repaired(), r.repaired(expected_merge=True)
        (True, False)
        """
        return bool((self.n_vertices_merged and not expected_merge)
                    or self.n_degenerate_faces_dropped or self.n_unreferenced_dropped
                    or self.n_polygons_self_crossing)

    def repairs(self) -> str:
        """The repairs in words, e.g. ``"merged 1 vertex, dropped 2 unreferenced vertices"``.

        Examples
        --------
        >>> from sns_np.mesh.io import LoadReport
        >>> LoadReport("m.obj", 6, 5, 0, 1, 1, 0, 4, 4).repairs()
        'merged 1 coincident vertex, dropped 1 degenerate face'
        """
        def count(n, what):
            return f"{n} {what}" if n == 1 else f"{n} " + what.replace("vertex", "vertice") + "s"
        parts = []
        if self.n_vertices_merged:
            parts.append(f"merged {count(self.n_vertices_merged, 'coincident vertex')}")
        if self.n_degenerate_faces_dropped:
            parts.append(f"dropped {count(self.n_degenerate_faces_dropped, 'degenerate face')}")
        if self.n_unreferenced_dropped:
            parts.append(f"dropped {count(self.n_unreferenced_dropped, 'unreferenced vertex')}")
        if self.n_polygons_self_crossing:
            parts.append(f"split {count(self.n_polygons_self_crossing, 'self-crossing polygon')} "
                         f"as fans that may fold (first at {self.self_crossing_example})")
        return ", ".join(parts) or "no repairs"

    @property
    def changed(self) -> bool:
        """True when the returned mesh differs from the file's own vertex and face lists."""
        return bool(self.n_polygons_triangulated or self.n_vertices_merged
                    or self.n_degenerate_faces_dropped or self.n_unreferenced_dropped)


def _read_obj(path):
    vs, polys, lines = [], [], []
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
                                        f"{_clip(line)!r}") from None
                if len(idx) < 3:
                    raise MeshFileError(f"{path}: line {lineno}: a face needs at least 3 "
                                        f"corners, got {len(idx)}")
                if 0 in idx:
                    raise MeshFileError(f"{path}: line {lineno}: vertex index 0 in a face; OBJ "
                                        "indices start at 1 (negative ones count back)")
                nv = len(vs)
                # OBJ indices are 1-based; negative ones count back from the latest vertex
                polys.append([i - 1 if i > 0 else nv + i for i in idx])
                lines.append(lineno)
    try:
        V = np.array(vs, dtype=np.float64).reshape(-1, 3)
    except ValueError as exc:
        raise MeshFileError(f"{path}: cannot parse vertex coordinates ({exc})") from None
    return V, polys, lambda f: f"{path}: line {lines[f]}"


def _read_off(path):
    with open(path, encoding="utf-8", errors="replace") as fh:
        tokens = [(i, ln.split("#", 1)[0].split()) for i, ln in enumerate(fh, 1)]
    lines = [(i, t) for i, t in tokens if t]
    if not lines or not lines[0][1][0].endswith("OFF"):
        raise MeshFileError(f"{path}: not an OFF file (the first line must be 'OFF')")
    if len(lines[0][1]) > 1:
        head, body = lines[0][1][1:], lines[1:]
    elif len(lines) > 1:
        head, body = lines[1][1], lines[2:]
    else:
        raise MeshFileError(f"{path}: the OFF header has no counts")
    try:
        nv, nf = int(head[0]), int(head[1])
        V = np.array([ln[:3] for _, ln in body[:nv]], dtype=np.float64).reshape(-1, 3)
    except (ValueError, IndexError) as exc:
        raise MeshFileError(f"{path}: malformed OFF data ({exc})") from None
    polys, where = [], [i for i, _ in body[nv:nv + nf]]
    for lineno, ln in body[nv:nv + nf]:
        try:
            k = int(ln[0])
            if k < 3 or len(ln) < 1 + k:
                raise ValueError(f"{k} corners declared, {len(ln) - 1} values given")
            polys.append([int(t) for t in ln[1:1 + k]])
        except ValueError as exc:
            raise MeshFileError(f"{path}: line {lineno}: malformed face ({exc}); a face "
                                "needs at least 3 corners") from None
    if V.shape[0] != nv or len(polys) != nf:
        raise MeshFileError(f"{path}: the header announces {nv} vertices and {nf} faces, the "
                            f"file holds {V.shape[0]} and {len(polys)}")
    return V, polys, lambda f: f"{path}: line {where[f]}"


def _clip(text, n=60):
    text = text.strip()
    return text if len(text) <= n else text[:n] + "..."


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
        Also return a :class:`LoadReport`. Without it, a :class:`MeshRepairWarning` names
        the repairs, if any (merged vertices, except in STL files, which always store a soup;
        dropped degenerate faces; dropped unreferenced vertices). The winding is never changed.

    Returns
    -------
    V : (n, 3) float array
    F : (m, 3) int array, the file's winding kept
    report : LoadReport, only when ``return_report`` is true

    Raises
    ------
    MeshFileError
        Missing or unreadable file, unsupported format, non-finite coordinates, out-of-range
        face indices (OBJ index 0 too), a face with fewer than 3 corners, a polygon without a
        fold-free triangulation, header counts that the data do not match, or an empty mesh;
        the message names the file and the line (OBJ, OFF, ASCII PLY) or the element.

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
            V, polys, where = _read_obj(path)
        elif ext == ".off":
            V, polys, where = _read_off(path)
        elif ext == ".ply":
            V, polys, where = read_ply(path)
        else:
            V, polys = _read_meshio_or_trimesh(path)
            where = lambda f: f"{path}: face {f}"  # noqa: E731
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
    for f, p in enumerate(polys):
        if len(p) < 3:
            raise MeshFileError(f"{where(f)}: a face needs at least 3 corners, got {len(p)}")
        lo, hi = min(p), max(p)
        if lo < 0 or hi >= n_read:
            raise MeshFileError(f"{where(f)}: a face refers to vertex {lo if lo < 0 else hi} "
                                f"(0-based) but the file has {n_read} vertices")
    F, n_poly, crossed = triangulate(V, polys)

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
    report = LoadReport(path=str(path), n_vertices_read=n_read, n_faces_read=f_read,
                        n_polygons_triangulated=n_poly, n_vertices_merged=n_merged,
                        n_degenerate_faces_dropped=n_bad, n_unreferenced_dropped=n_unused,
                        n_vertices=V.shape[0], n_faces=F.shape[0],
                        n_polygons_self_crossing=len(crossed),
                        self_crossing_example=where(crossed[0]) if crossed else "")
    if not return_report:
        if report.repaired(expected_merge=ext == ".stl"):
            warnings.warn(f"{path}: {report.repairs()}; pass return_report=True for the "
                          "counts", MeshRepairWarning, stacklevel=2)
        return V, F
    return V, F, report

