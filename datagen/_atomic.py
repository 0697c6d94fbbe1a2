"""Atomic file writes: a reader sees the old file or the complete new one, never a partial one.

Every library writer goes through here: the new content is written to a temporary file in the
target's directory (same filesystem), flushed to disk, then renamed over the target with
``os.replace`` (atomic on POSIX). A failure while writing leaves the target untouched and removes
the temporary file. The result gets the permissions a plain ``open`` would give it (0666 or, for
a folder, 0777, less the umask), not the temporary file's private 0600.

    atomic_write_text(path, text)
    with atomic_path(path) as tmp:      # for writers that want a path (pyarrow, numpy, ...)
        pq.write_table(table, tmp)
    with atomic_dir(path) as tmp:       # a folder of files: all of them or none
        (tmp / "a.obj").write_text(...)
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_dir", "atomic_path", "atomic_write_bytes", "atomic_write_text"]


def _umask() -> int:
    """The process's umask: from /proc (Linux), else by setting it and setting it back."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | Path, *, fsync: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on a clean exit it replaces ``path``.

    The parent directory must exist. ``fsync``: flush the new file to disk before the rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if fsync:
            with open(tmp_path, "rb+") as fh:
                os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def atomic_write_bytes(path: str | Path, data: bytes, *, fsync: bool = True) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path, fsync=fsync) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | Path, text: str, *, fsync: bool = True) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"), fsync=fsync)


@contextlib.contextmanager
def atomic_dir(path: str | Path) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``path``; on a clean exit it replaces ``path`` (an
    existing folder there is removed first: for a moment there is none, never a partial one). A
    failure (an interrupt included) removes the temporary folder and leaves ``path`` as it was.

    The parent directory must exist."""
    path = Path(path)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
