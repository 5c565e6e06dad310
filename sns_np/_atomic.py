"""Atomic, durable file and folder writes, shared by every writer of the package (private).

A file is written under a temporary name in its final folder, flushed to disk (``fsync``),
renamed onto the final name (``os.replace``, atomic on POSIX and Windows) and the folder's
entry is flushed too. A crash or Ctrl-C at any point leaves either the old file or the new
one, never a truncated file under the final name.

The temporary file is created with ``os.open(..., 0o666)``, so it gets the permissions the
user's umask gives any new file (typically 0644), as ``open(path, "w")`` would; not the 0600
that ``tempfile.mkstemp`` leaves (which made model files unreadable to a group that shares
them). Folders likewise get ``0o777`` minus the umask, not ``mkdtemp``'s 0700.

Temporary names are ``<name>.<random>.tmp`` beside the final file; :func:`stale_temporaries`
lists those left behind by a killed process (``kill -9``), so that a later run can remove them.

:func:`exclusive` keeps two processes from writing the same output at once: it holds an
advisory lock on ``<name>.lock`` (``flock``; released by the kernel when the holder dies, even
by ``kill -9``), and a second writer gets an :class:`OutputBusyError` naming the holder.
Only the lock's holder may remove the stale temporaries of its output
(:func:`remove_stale_temporaries`), since another live writer's temporaries look the same.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import socket
from pathlib import Path

__all__ = ["write_file", "write_folder", "stale_temporaries", "remove_stale_temporaries",
           "exclusive", "OutputBusyError", "fsync_file", "fsync_dir"]


def _temporary_name(path: Path) -> Path:
    return path.with_name(f"{path.name}.{secrets.token_hex(4)}.tmp")


def stale_temporaries(path) -> list[Path]:
    """Temporary files or folders of ``path`` (``<name>.<random>.tmp``) left in its folder."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        return []
    return sorted(parent.glob(f"{_glob_escape(path.name)}.*.tmp"))


def remove_stale_temporaries(path) -> list[Path]:
    """Remove the temporaries of ``path`` left by a killed writer; returns what was removed.

    Call it only while holding :func:`exclusive` on ``path``: a live writer's temporary file
    has the same form of name.
    """
    removed = []
    for tmp in stale_temporaries(path):
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        removed.append(tmp)
    return removed


class OutputBusyError(OSError):
    """Another process holds the lock of an output (see :func:`exclusive`)."""


def _try_lock(fd) -> bool:
    """Take a non-blocking exclusive lock on an open file; False when another holds it."""
    try:
        import fcntl
    except ImportError:                                     # pragma: no cover - Windows
        import msvcrt
        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except (BlockingIOError, PermissionError):
        return False
    return True


@contextlib.contextmanager
def exclusive(path):
    """Hold the lock file ``<path>.lock`` while writing ``path``; yields the lock's path.

    A second holder, in this process or another, gets an :class:`OutputBusyError` naming the
    holder's process id and host. The lock file is removed on exit; one left by a killed
    process is no longer locked and is simply taken over.
    """
    path = Path(path)
    lock = path.with_name(path.name + ".lock")
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        if not _try_lock(fd):
            holder = os.read(fd, 200).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise OutputBusyError(
                f"{str(path)!r} is being written by another process ({holder}; lock file "
                f"{str(lock)!r}); wait for it to finish or choose another output")
        # a finishing holder may have removed the file between our open and our lock
        try:
            same = os.path.samestat(os.fstat(fd), os.stat(lock))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"process {os.getpid()} on {socket.gethostname()}\n".encode())
        yield lock
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock)                 # still holding it: no one can take it in between
        os.close(fd)


def _glob_escape(name: str) -> str:
    return "".join(f"[{c}]" if c in "*?[" else c for c in name)


def fsync_file(path) -> None:
    """Flush a file's data to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path) -> None:
    """Flush a folder's entries (a rename into it) to disk; a no-op where folders cannot be
    opened (Windows)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse fsync on a folder: nothing more to do
        pass
    finally:
        os.close(fd)


def _create_exclusive(path: Path) -> Path:
    """Create an empty file with a fresh temporary name next to ``path`` (umask applies)."""
    for _ in range(100):
        tmp = _temporary_name(path)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0),
                         0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(f"could not create a temporary file next to {str(path)!r}")


def _check_folder(path: Path) -> Path:
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise OSError(f"directory {str(directory)!r} does not exist")
    return directory


def write_file(path, write) -> Path:
    """Call ``write(tmp)`` on a temporary file next to ``path``, then move it onto ``path``.

    ``tmp`` is a :class:`~pathlib.Path` of an existing empty file with the permissions of a
    new file under the user's umask; ``write`` may reopen it by name (``open(tmp, "wb")``,
    meshio, matplotlib). After it returns, the data is fsynced, the file renamed onto
    ``path`` and the folder fsynced. On any error (or Ctrl-C) the temporary file is removed
    and ``path`` is left as it was.
    """
    path = Path(path)
    directory = _check_folder(path)
    tmp = _create_exclusive(path)
    try:
        write(tmp)
        fsync_file(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    fsync_dir(directory)
    return path


def _fsync_tree(root: Path) -> None:
    for folder, _, files in os.walk(root):
        for name in files:
            fsync_file(os.path.join(folder, name))
        fsync_dir(folder)


def _make_folder(path: Path) -> Path:
    for _ in range(100):
        tmp = _temporary_name(path)
        try:
            os.mkdir(tmp, 0o777)
        except FileExistsError:
            continue
        return tmp
    raise FileExistsError(f"could not create a temporary folder next to {str(path)!r}")


def write_folder(out, write, overwrite=False) -> Path:
    """Write a folder through a temporary sibling and rename it into place.

    ``write(tmp)`` fills the folder ``tmp``; then every file in it is fsynced and the folder
    renamed onto ``out``. On any error the temporary folder is removed, so ``out`` is either
    absent, untouched or complete. An existing non-empty ``out`` is refused unless
    ``overwrite``, in which case it is replaced (moved aside, then deleted).
    """
    out = Path(out)
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise OSError(f"parent folder {str(parent)!r} of the output does not exist")
    if out.exists() and not out.is_dir():
        raise OSError(f"output {str(out)!r} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise OSError(f"output folder {str(out)!r} exists and is not empty; remove it or "
                      f"choose another")
    tmp = _make_folder(out)
    try:
        write(tmp)
        _fsync_tree(tmp)
        old = None
        if out.exists():
            old = _temporary_name(out)
            os.rename(out, old)
        os.rename(tmp, out)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    fsync_dir(parent)
    return out
