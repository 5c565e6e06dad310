"""A strict PLY reader (ASCII and binary): vertex positions and face corner lists.

Every count in the header is checked against the data before anything of that size is
allocated: a file that holds fewer (or more) vertices or faces than it declares, a face that
uses a vertex the file does not declare, or a header that announces more data than the file
can hold raises :class:`MeshFileError` naming the file, the element and, for ASCII files, the
line. Elements other than ``vertex`` and ``face`` and properties other than ``x y z`` and
``vertex_indices`` (or ``vertex_index``) are read past and ignored.
"""

from __future__ import annotations

import numpy as np

from .errors import MeshFileError

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_MAX_HEADER = 1 << 20


class _Element:
    def __init__(self, name, count, line):
        self.name, self.count, self.line = name, count, line
        self.props = []                     # (name, dtype) or (name, (count_dtype, item_dtype))

    @property
    def has_lists(self):
        return any(isinstance(t, tuple) for _, t in self.props)


def _header(path, raw):
    end = raw.find(b"end_header", 0, _MAX_HEADER)
    if not raw.startswith(b"ply") or end < 0:
        raise MeshFileError(f"cannot read mesh file {path}: not a PLY file (it must start with "
                            "'ply' and have an 'end_header' line within 1 MB)")
    stop = raw.find(b"\n", end)
    stop = len(raw) if stop < 0 else stop + 1
    lines = raw[:stop].decode("ascii", errors="replace").splitlines()
    fmt, elements = None, []
    for lineno, line in enumerate(lines, 1):
        t = line.split()
        if not t or t[0] in ("ply", "comment", "obj_info", "end_header"):
            continue
        bad = f"{path}: line {lineno}: malformed PLY header line {line.strip()!r}"
        if t[0] == "format":
            if len(t) != 3 or t[1] not in ("ascii", "binary_little_endian",
                                          "binary_big_endian"):
                raise MeshFileError(bad)
            fmt = t[1]
        elif t[0] == "element":
            if len(t) != 3 or not t[2].isdigit():
                raise MeshFileError(bad)
            elements.append(_Element(t[1], int(t[2]), lineno))
        elif t[0] == "property":
            if not elements:
                raise MeshFileError(bad + " (a property before any element)")
            if len(t) == 3 and t[1] in _TYPES:
                elements[-1].props.append((t[2], _TYPES[t[1]]))
            elif len(t) == 5 and t[1] == "list" and t[2] in _TYPES and t[3] in _TYPES:
                elements[-1].props.append((t[4], (_TYPES[t[2]], _TYPES[t[3]])))
            else:
                raise MeshFileError(bad)
        else:
            raise MeshFileError(bad)
    if fmt is None:
        raise MeshFileError(f"{path}: the PLY header has no 'format' line")
    return fmt, elements, stop, len(lines)


def read_ply(path):
    """Vertex positions V (n, 3) float64 and face corner lists of a PLY file.

    Returns (V, polys, where) with ``where(f)`` naming face f for messages.
    """
    raw = path.read_bytes()
    fmt, elements, start, n_header_lines = _header(path, raw)
    names = [e.name for e in elements]
    for want in ("vertex", "face"):
        if names.count(want) != 1:
            raise MeshFileError(f"{path}: expected one '{want}' element in the PLY header, "
                                f"found {names.count(want)}")
    vert, face = elements[names.index("vertex")], elements[names.index("face")]
    pnames = [p for p, _ in vert.props]
    for c in "xyz":
        if c not in pnames or isinstance(vert.props[pnames.index(c)][1], tuple):
            raise MeshFileError(f"{path}: the PLY 'vertex' element has no scalar property {c!r}")
    fnames = [p for p, _ in face.props]
    key = next((k for k in ("vertex_indices", "vertex_index") if k in fnames), None)
    if key is None or not isinstance(face.props[fnames.index(key)][1], tuple):
        raise MeshFileError(f"{path}: the PLY 'face' element has no list property "
                            "'vertex_indices' (triangle strips and other layouts are not read)")
    if fmt == "ascii":
        data = _read_ascii(path, raw[start:], elements, n_header_lines)
    else:
        data = _read_binary(path, raw[start:], elements, "<" if "little" in fmt else ">")
    cols = data["vertex"]
    V = np.stack([np.asarray(cols[c], dtype=np.float64) for c in "xyz"], axis=1)
    polys = data["face"][key]
    nv = V.shape[0]
    lines = data.get("_face_lines")

    def where(f):
        return f"{path}: face {f}" + (f" (line {lines[f]})" if lines is not None else "")

    for f, p in enumerate(polys):
        if len(p) and (min(p) < 0 or max(p) >= nv):
            bad = min(p) if min(p) < 0 else max(p)
            raise MeshFileError(f"{where(f)} uses vertex {bad}, but the 'vertex' element "
                                f"declares {nv} vertices (0-based indices 0..{nv - 1})")
    return V, polys, where


def _read_ascii(path, body, elements, lineno):
    lines = body.decode("ascii", errors="replace").splitlines()
    out, pos = {}, 0
    for e in elements:
        cols = {name: [] for name, _ in e.props}
        face_lines = []
        for i in range(e.count):
            while pos < len(lines) and not lines[pos].strip():
                pos += 1
            if pos >= len(lines):
                raise MeshFileError(f"{path}: the PLY header (line {e.line}) declares {e.count} "
                                    f"'{e.name}' elements but the file holds only {i}")
            here = lineno + pos + 1
            t = lines[pos].split()
            pos += 1
            j = 0
            try:
                for name, typ in e.props:
                    if isinstance(typ, tuple):
                        m = int(t[j])
                        if m < 0 or j + 1 + m > len(t):
                            raise ValueError(f"a list of {m} values")
                        cols[name].append([int(v) for v in t[j + 1:j + 1 + m]])
                        j += 1 + m
                    else:
                        cols[name].append(t[j])
                        j += 1
                if j != len(t):
                    raise ValueError(f"{len(t)} values where the header describes {j}")
            except (ValueError, IndexError) as exc:
                raise MeshFileError(f"{path}: line {here}: malformed '{e.name}' element {i} "
                                    f"({exc})") from None
            face_lines.append(here)
        if e.name == "vertex":
            try:
                cols = {c: np.array(cols[c], dtype=np.float64) for c in "xyz"}
            except ValueError as exc:
                raise MeshFileError(f"{path}: malformed vertex coordinates ({exc})") from None
        if e.name == "face":
            out["_face_lines"] = face_lines
        out[e.name] = cols
    rest = [i for i in range(pos, len(lines)) if lines[i].strip()]
    if rest:
        raise MeshFileError(f"{path}: line {lineno + rest[0] + 1}: data after the last "
                            f"element the header declares")
    return out


def _read_binary(path, body, elements, order):
    out, off = {}, 0
    for e in elements:
        if not e.has_lists:
            dt = np.dtype([(f"p{i}", order + t) for i, (_, t) in enumerate(e.props)])
            need = e.count * dt.itemsize
            if off + need > len(body):
                held = (len(body) - off) // max(dt.itemsize, 1)
                raise MeshFileError(f"{path}: the PLY header (line {e.line}) declares {e.count} "
                                    f"'{e.name}' elements but the file holds only {held}")
            rec = np.frombuffer(body, dtype=dt, count=e.count, offset=off)
            out[e.name] = {name: rec[f"p{i}"] for i, (name, _) in enumerate(e.props)}
            off += need
            continue
        out[e.name], off = _read_binary_lists(path, body, e, order, off)
    if off != len(body):
        raise MeshFileError(f"{path}: {len(body) - off} bytes after the last element the "
                            "header declares")
    return out


def _read_binary_lists(path, body, e, order, off):
    """An element with list properties: all triangles at once when possible, else one by one."""
    if len(e.props) == 1:
        name, (ct, it) = e.props[0]
        dt = np.dtype([("n", order + ct), ("i", order + it, (3,))])
        if off + e.count * dt.itemsize <= len(body):
            rec = np.frombuffer(body, dtype=dt, count=e.count, offset=off)
            if np.all(rec["n"] == 3):
                return {name: rec["i"].astype(np.int64).tolist()}, off + e.count * dt.itemsize
    cols = {name: [] for name, _ in e.props}
    for i in range(e.count):
        for name, typ in e.props:
            ct, it = typ if isinstance(typ, tuple) else (None, typ)
            if ct is not None:
                cdt = np.dtype(order + ct)
                if off + cdt.itemsize > len(body):
                    break
                m = int(np.frombuffer(body, dtype=cdt, count=1, offset=off)[0])
                off += cdt.itemsize
                idt = np.dtype(order + it)
                if m < 0 or off + m * idt.itemsize > len(body):
                    break
                cols[name].append(np.frombuffer(body, dtype=idt, count=m, offset=off)
                                  .astype(np.int64).tolist())
                off += m * idt.itemsize
            else:
                sdt = np.dtype(order + it)
                if off + sdt.itemsize > len(body):
                    break
                cols[name].append(np.frombuffer(body, dtype=sdt, count=1, offset=off)[0])
                off += sdt.itemsize
        else:
            continue
        raise MeshFileError(f"{path}: the PLY header (line {e.line}) declares {e.count} "
                            f"'{e.name}' elements but the file holds only {i}")
    return cols, off
