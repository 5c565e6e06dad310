"""Reading .npz model files at a cost bounded by the file's honest size, and writing them
atomically (:func:`save_npz`).

An .npz file is a zip archive of .npy arrays. ``numpy.load`` allocates each array from the
shape its header declares before reading a byte of data, and a zip member may unpack to far
more than it occupies: a crafted 70 KB file can make it allocate gigabytes. Here nothing is
allocated before the declared sizes have been checked:

* the archive: at most ``MAX_MEMBERS`` members, no encryption, and the members' declared
  uncompressed sizes (``ZipInfo.file_size``) sum to at most ``MAX_RATIO`` times the file's
  size plus ``SLACK_BYTES`` (a zip bomb is refused from its directory alone);
* each array, when first asked for: its .npy header is read (``numpy.lib.format``), object
  dtypes are refused (never unpickled), and header plus ``prod(shape) * itemsize`` must equal
  the member's uncompressed size exactly;
* callers compare the declared shapes and dtypes (:meth:`NpzReader.declared`) with what they
  expect, e.g. the parameter count that the architecture fields imply, before reading.

Reading then fills an array of that checked size (``zipfile`` never yields more bytes than
``file_size``, and checks the CRC at the end). Every failure is a :class:`ModelFileError`
naming the file and the field.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np
from numpy.lib import format as npy_format

from ._atomic import write_file
from .errors import ModelFileError

#: an archive with more members than this is not a model file
MAX_MEMBERS = 4096
#: members may unpack to at most MAX_RATIO * file size + SLACK_BYTES bytes in total
MAX_RATIO = 4
SLACK_BYTES = 64 << 20
#: nesting depth allowed in JSON metadata
MAX_JSON_DEPTH = 64
_CHUNK = 1 << 22


def save_npz(path, arrays: dict) -> Path:
    """Write ``arrays`` to ``path`` (.npz) through a temporary file, fsync and an atomic rename.

    The file gets the permissions of the user's umask, and the data is on disk before the
    rename (:func:`sns_np._atomic.write_file`): ``path`` is either untouched or complete.
    """
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise ValueError(f"model files must end in .npz, got {path.name!r}")

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)

    return write_file(path, write)


class load_npz:
    """Context manager opening an .npz file for checked reading, never unpickling.

    Missing, unreadable, non-npz or oversized files raise :class:`ModelFileError` naming the
    file. The value of the ``with`` statement is an :class:`NpzReader`.
    """

    def __init__(self, path):
        self.path = Path(path)
        self._zip = None

    def __enter__(self) -> NpzReader:
        path = self.path
        if not path.is_file():
            raise ModelFileError(f"model file {str(path)!r} does not exist")
        if not zipfile.is_zipfile(path):
            # np.load would try other formats (and blame pickles for a text file): say plainly
            with open(path, "rb") as fh:
                magic = fh.read(6)
            if magic == b"\x93NUMPY":
                raise ModelFileError(f"{path}: not an .npz archive (a single .npy array?)")
            raise ModelFileError(f"{path}: not a readable .npz model file (not a zip archive)")
        try:
            self._zip = zipfile.ZipFile(path)
            infos = self._zip.infolist()
        except Exception as exc:  # BadZipFile, OSError, ValueError, NotImplementedError...
            self._close()
            raise ModelFileError(f"{path}: not a readable .npz model file ({exc})") from None
        try:
            members = _check_archive(path, infos)
        except ModelFileError:
            self._close()
            raise
        return NpzReader(self._zip, members, str(path))

    def __exit__(self, *exc):
        self._close()
        return False

    def _close(self):
        if self._zip is not None:
            self._zip.close()
            self._zip = None


def _check_archive(path, infos):
    if len(infos) > MAX_MEMBERS:
        raise ModelFileError(f"{path}: the archive has {len(infos)} members; a model file has "
                             f"at most {MAX_MEMBERS}")
    size = path.stat().st_size
    total = sum(i.file_size for i in infos)
    if total > MAX_RATIO * size + SLACK_BYTES:
        raise ModelFileError(
            f"{path}: the archive's members unpack to {total:,} bytes, more than {MAX_RATIO} "
            f"times the file's {size:,} bytes plus {SLACK_BYTES >> 20} MiB (a zip bomb?); "
            f"refused before reading")
    members = {}
    for info in infos:
        if info.flag_bits & 0x1:
            raise ModelFileError(f"{path}: member {info.filename!r} is encrypted")
        key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
        members[key] = info
    return members


class NpzReader:
    """Checked access to the arrays of an open .npz archive (see the module notes).

    ``key in reader``, ``reader.files``, ``reader.declared(key)`` (shape and dtype from the
    .npy header, no data read), ``reader[key]`` (the array) and ``reader.read_into(key, out)``.
    """

    def __init__(self, zf, members, name):
        self._zip, self._members, self._name = zf, members, name
        self._headers = {}

    @property
    def files(self):
        return list(self._members)

    def __contains__(self, key):
        return key in self._members

    def _fail(self, key, why):
        return ModelFileError(f"{self._name}: field {key!r} {why}")

    def declared(self, key):
        """(shape, dtype) of field ``key`` as its header declares them, checked against the
        member's size; nothing else is read."""
        if key not in self._headers:
            self._headers[key] = self._read_header(key)
        shape, dtype, _, _ = self._headers[key]
        return shape, dtype

    def _read_header(self, key):
        info = self._members[key]
        try:
            with self._zip.open(info) as fp:
                version = npy_format.read_magic(fp)
                if version == (1, 0):
                    shape, fortran, dtype = npy_format.read_array_header_1_0(fp)
                elif version == (2, 0):
                    shape, fortran, dtype = npy_format.read_array_header_2_0(fp)
                else:
                    raise ValueError(f".npy format version {version} is not read")
                offset = fp.tell()
        except Exception as exc:  # ValueError, BadZipFile, zlib.error, EOFError, SyntaxError...
            raise self._fail(key, f"is not a readable .npy array ({_one_line(exc)})") from None
        if dtype.hasobject:
            raise self._fail(key, "cannot be read safely: it holds Python objects, which "
                                  "are never unpickled")
        if any(int(n) < 0 for n in shape):
            raise self._fail(key, f"declares a negative shape {shape}")
        nbytes = math.prod(int(n) for n in shape) * dtype.itemsize
        if offset + nbytes != info.file_size:
            raise self._fail(key, f"declares shape {shape} of {dtype} ({nbytes:,} bytes) but "
                                  f"its archive member holds {info.file_size - offset:,}")
        return tuple(int(n) for n in shape), dtype, bool(fortran), offset

    def __getitem__(self, key):
        shape, dtype = self.declared(key)
        fortran = self._headers[key][2]
        out = np.empty(shape[::-1] if fortran else shape, dtype=dtype)
        self._fill(key, out)
        return out.T if fortran else out

    def read_into(self, key, out):
        """Read field ``key`` into the C-contiguous array ``out`` of its declared shape and
        dtype (checked by the caller with :meth:`declared`)."""
        shape, dtype = self.declared(key)
        if shape != out.shape or dtype != out.dtype or not out.flags.c_contiguous or (
                self._headers[key][2] and len(shape) > 1):
            raise self._fail(key, f"has shape {shape} and dtype {dtype}; expected {out.shape} "
                                  f"{out.dtype}")
        self._fill(key, out)
        return out

    def _fill(self, key, out):
        offset = self._headers[key][3]
        buf = memoryview(out.reshape(-1).view(np.uint8)) if out.size else memoryview(b"")
        try:
            with self._zip.open(self._members[key]) as fp:
                fp.read(offset)
                pos = 0
                while pos < len(buf):
                    got = fp.readinto(buf[pos:pos + _CHUNK])
                    if not got:
                        raise EOFError(f"data ends after {pos} of {len(buf)} bytes")
                    pos += got
                fp.read(1)                                  # reach the end: CRC check
        except Exception as exc:
            raise self._fail(key, f"is corrupt ({_one_line(exc)})") from None


def _one_line(exc):
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}"[:200]


# ---------------------------------------------------------------------------------------------
# typed fields: checked before they are read
# ---------------------------------------------------------------------------------------------

def declared(data, key):
    """(shape, dtype) of ``data[key]`` for an :class:`NpzReader` or a dict of arrays."""
    if isinstance(data, NpzReader):
        return data.declared(key)
    a = np.asarray(data[key])
    return a.shape, a.dtype


def field(data, key, source, *, kinds, shape=(), what="a value"):
    """Field ``key`` of ``data`` after checking its declared shape and dtype kind.

    Parameters
    ----------
    data : NpzReader or dict of arrays
    kinds : str, allowed ``dtype.kind`` letters ("iu" integers, "f" floats, "U" text, "b")
    shape : tuple, the required shape (``()`` for a scalar)
    what : str, what the field should hold, for the message

    Returns a Python scalar for ``shape == ()``, else the array.
    """
    if key not in data:
        raise ModelFileError(f"{source}: missing field {key!r}")
    s, dt = declared(data, key)
    if s != tuple(shape) or dt.kind not in kinds:
        got = f"{dt} of shape {s}"
        raise ModelFileError(f"{source}: field {key!r} must be {what}, got {got}")
    value = np.asarray(data[key])
    return value.item() if value.shape == () else value


def int_field(data, key, source, minimum=None):
    """An integer scalar field (``minimum`` inclusive), as a Python int."""
    v = field(data, key, source, kinds="iu", what="an integer")
    if minimum is not None and v < minimum:
        raise ModelFileError(f"{source}: field {key!r} must be >= {minimum}, got {v}")
    return int(v)


def json_field(data, key, source, max_depth=MAX_JSON_DEPTH):
    """A text field holding JSON, parsed; at most ``max_depth`` levels of nesting."""
    text = field(data, key, source, kinds="U", what="JSON text")
    try:
        value = json.loads(text)
    except RecursionError:
        raise ModelFileError(f"{source}: field {key!r} is nested too deeply (more than "
                             f"{max_depth} levels)") from None
    except ValueError as exc:
        raise ModelFileError(f"{source}: field {key!r} is not valid JSON ({exc})") from None
    if json_depth(value) > max_depth:
        raise ModelFileError(f"{source}: field {key!r} is nested too deeply (more than "
                             f"{max_depth} levels)")
    return value


def json_depth(value) -> int:
    """Nesting depth of a parsed JSON value (0 for a scalar), without recursion."""
    depth, stack = 0, [(value, 0)]
    while stack:
        v, d = stack.pop()
        depth = max(depth, d)
        if isinstance(v, dict):
            stack.extend((x, d + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, d + 1) for x in v)
    return depth
