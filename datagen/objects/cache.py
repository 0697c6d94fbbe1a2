"""Content-addressed, atomically written cache of processed objects.

Layout: ``<root>/objects/<key[:2]>/<key>-<config hash[:16]>/``, the key being
``process.object_key`` (the raw mesh sha256 with the file type and any existing pieces) (see ``layout.py`` for the
files inside). An entry is built in ``<root>/tmp/<random>/`` and renamed into place in one
``os.rename``; a process killed mid-way leaves only a temp dir (removed by
``clean_stale_temp``), never a half entry. The root is ``$DATAGEN_CACHE`` or
``~/.cache/datagen``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import time
from pathlib import Path

__all__ = ["cache_root", "entry_dir", "atomic_entry", "clean_stale_temp"]


def cache_root(root: str | Path | None = None) -> Path:
    """The cache root: ``root`` if given, else $DATAGEN_CACHE, else ~/.cache/datagen."""
    if root is not None:
        return Path(root)
    env = os.environ.get("DATAGEN_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "datagen"


def entry_dir(root: Path, object_key: str, config_hash: str) -> Path:
    """Directory of the entry keyed by (object key, processing config hash)."""
    if len(object_key) != 64 or len(config_hash) < 16:
        raise ValueError(f"cache key needs a 64-hex object key and a config hash, "
                         f"got {object_key!r}, {config_hash!r}")
    return root / "objects" / object_key[:2] / f"{object_key}-{config_hash[:16]}"


@contextlib.contextmanager
def atomic_entry(final: Path):
    """Yield a temp dir to fill; on success rename it to ``final`` (a no-op if another process
    won the race); on any exception (KeyboardInterrupt included) delete it and re-raise."""
    tmp_root = final.parents[2] / "tmp"
    tmp_root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=final.name[:24] + ".", dir=tmp_root))
    try:
        yield tmp
        final.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(tmp, final)
        except OSError:
            if not final.is_dir():
                raise
            shutil.rmtree(tmp, ignore_errors=True)  # someone else finished the same entry
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def clean_stale_temp(root: Path, older_than_s: float = 6 * 3600) -> int:
    """Remove temp dirs left by killed processes; returns how many were removed."""
    tmp_root = root / "tmp"
    if not tmp_root.is_dir():
        return 0
    now, n = time.time(), 0
    for d in tmp_root.iterdir():
        if now - d.stat().st_mtime > older_than_s:
            shutil.rmtree(d, ignore_errors=True)
            n += 1
    return n
