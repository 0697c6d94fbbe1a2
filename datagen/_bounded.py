"""Bounded reads of a user's files: regular files only, each kind with a size cap.

Every library reader of a path someone gave (a manifest, a config, a hand spec, a task YAML, a
mesh, a job's own JSON files) opens it through here. A device (``/dev/zero``), a FIFO, a socket
or a directory is refused at once, before a byte is read (a FIFO is opened non-blocking, so no
writer is waited for); a file over its kind's cap is refused from its size, and a file that grows
while it is read is cut at the cap plus one byte and refused too. Memory stays bounded by the cap.

    text = read_text(path, CONFIG_BYTES, "job config")      # InputError naming path and reason
    digest, size = sha256_file(path, mesh_cap, "mesh")       # streamed: memory ~ one chunk

`InputError` (a `DatagenError` and a ValueError: the command line prints it as one line, exit 2)
carries ``path``, a reason code (`NOT_FOUND`, `NOT_REGULAR`, `TOO_LARGE`, `UNREADABLE`,
`NOT_TEXT`) and the detail without the path, so a caller can re-raise it as its own domain error.
"""

from __future__ import annotations

import errno
import hashlib
import os
import stat
from pathlib import Path

from datagen.errors import DatagenError

__all__ = ["CONFIG_BYTES", "HAND_SPEC_BYTES", "InputError", "JSON_BYTES", "MANIFEST_BYTES", "MANIFEST_LINE_BYTES",
           "NOT_FOUND", "NOT_REGULAR", "NOT_TEXT", "TOO_LARGE", "UNREADABLE", "check_regular", "iter_lines", "open_regular",
           "read_bytes", "read_json", "read_text", "sha256_file"]

CONFIG_BYTES = 1 << 20            #: job, processing, synthesis and evaluation configs, task YAMLs (a few kB)
HAND_SPEC_BYTES = 8 << 20         #: hand spec YAMLs (LEAP's, with its sphere lists, is 94 kB)
MANIFEST_BYTES = 1 << 30          #: a manifest (~300 bytes per object: ~3.5 million objects)
MANIFEST_LINE_BYTES = 1 << 20     #: one manifest line
JSON_BYTES = 16 << 20             #: a job's own JSON files (job.json, ledger entries, meta.json)
_CHUNK = 1 << 20

# reason codes
NOT_FOUND, NOT_REGULAR, TOO_LARGE, UNREADABLE, NOT_TEXT = ("missing_file", "not_a_regular_file", "file_too_large",
                                                            "unreadable", "not_text")


class InputError(DatagenError, ValueError):
    """A path that cannot be read as a file of its kind; ``str()`` is ``"<path>: <detail>"``."""

    def __init__(self, path: str | Path, reason: str, detail: str, remedy: str = "") -> None:
        self.path, self.reason, self.detail = str(path), reason, detail
        super().__init__(f"{path}: {detail}", remedy)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _size(n: int) -> str:
    for unit, k in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 1 << k:
            return f"{n / (1 << k):.4g} {unit}"
    return f"{n} bytes"


def open_regular(path: str | Path, limit: int, what: str) -> tuple[int, int]:
    """``(fd, size)`` of ``path`` opened for reading, or `InputError`: missing, not a regular file
    (checked on the open descriptor: no race with a swapped file), over ``limit`` bytes. The caller
    closes ``fd``."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # a FIFO opens without a writer
    except FileNotFoundError:
        raise InputError(path, NOT_FOUND, f"the {what} file does not exist") from None
    except OSError as exc:
        if exc.errno == errno.ENXIO:  # opening a Unix socket
            raise InputError(path, NOT_REGULAR, f"the {what} is a socket, not a regular file") from None
        if exc.errno == errno.EISDIR:
            raise InputError(path, NOT_REGULAR, f"the {what} is a directory, not a regular file") from None
        raise InputError(path, UNREADABLE, f"cannot open the {what}: {exc.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(path, NOT_REGULAR, f"the {what} is {_kind(st.st_mode)}, not a regular file")
        if st.st_size > limit:
            raise InputError(path, TOO_LARGE, f"the {what} is {_size(st.st_size)}, over its limit of {_size(limit)}")
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd, st.st_size


def check_regular(path: str | Path, limit: int, what: str) -> None:
    """`InputError` if ``path`` is not a regular file of at most ``limit`` bytes (as `open_regular`,
    nothing read): a command checks its arguments with it before its heavy imports."""
    fd, _ = open_regular(path, limit, what)
    os.close(fd)


def read_bytes(path: str | Path, limit: int, what: str) -> bytes:
    """The bytes of regular file ``path``, at most ``limit`` of them (`InputError` otherwise)."""
    fd, _ = open_regular(path, limit, what)
    try:
        with os.fdopen(fd, "rb", closefd=False) as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise InputError(path, UNREADABLE, f"cannot read the {what}: {exc.strerror}") from None
    finally:
        os.close(fd)
    if len(data) > limit:  # it grew while being read
        raise InputError(path, TOO_LARGE, f"the {what} is over its limit of {_size(limit)}")
    return data


def read_text(path: str | Path, limit: int, what: str) -> str:
    """`read_bytes` decoded as UTF-8 (`InputError` reason `NOT_TEXT` if it is not)."""
    data = read_bytes(path, limit, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(path, NOT_TEXT, f"the {what} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def read_json(path: str | Path, what: str, limit: int = JSON_BYTES):
    """The JSON document in ``path`` (`InputError` naming the file for an empty, truncated or
    malformed one: reason `NOT_TEXT`)."""
    import json

    text = read_text(path, limit, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        detail = "empty" if not text.strip() else f"not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})"
        raise InputError(path, NOT_TEXT, f"the {what} is {detail}") from None
    except RecursionError:
        raise InputError(path, NOT_TEXT, f"the {what} is nested too deeply") from None


def iter_lines(path: str | Path, limit: int, line_limit: int, what: str):
    """Yield ``(number, line)`` of a UTF-8 text file, one line in memory at a time (1-based
    numbers; the newline kept off). `InputError` for a file over ``limit`` bytes, a line over
    ``line_limit`` or bytes that are not UTF-8 (naming the line)."""
    fd, _ = open_regular(path, limit, what)
    total = 0
    with os.fdopen(fd, "rb") as fh:
        for n, raw in enumerate(iter(lambda: fh.readline(line_limit + 1), b""), 1):
            total += len(raw)
            if total > limit:
                raise InputError(path, TOO_LARGE, f"the {what} is over its limit of {_size(limit)}")
            if len(raw) > line_limit and not raw.endswith(b"\n"):
                raise InputError(f"{path}:{n}", TOO_LARGE, f"line longer than {_size(line_limit)}")
            try:
                yield n, raw.decode("utf-8").rstrip("\r\n")
            except UnicodeDecodeError as exc:
                raise InputError(f"{path}:{n}", NOT_TEXT, f"not UTF-8 text ({exc.reason})") from None


def sha256_file(path: str | Path, limit: int, what: str) -> tuple[str, int]:
    """``(sha256 hex, size in bytes)`` of a regular file, read in 1 MiB chunks (`InputError` as
    `read_bytes`)."""
    fd, _ = open_regular(path, limit, what)
    digest, size = hashlib.sha256(), 0
    try:
        with os.fdopen(fd, "rb", closefd=False) as fh:
            for chunk in iter(lambda: fh.read(_CHUNK), b""):
                size += len(chunk)
                if size > limit:
                    raise InputError(path, TOO_LARGE, f"the {what} is over its limit of {_size(limit)}")
                digest.update(chunk)
    except OSError as exc:
        raise InputError(path, UNREADABLE, f"cannot read the {what}: {exc.strerror}") from None
    finally:
        os.close(fd)
    return digest.hexdigest(), size
