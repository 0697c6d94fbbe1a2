"""Object processing in a separate process with a time limit.

CoACD is native code: on a bad mesh it can run for hours or crash the interpreter. Processing an
object in a child process bounds both: a child killed after ``timeout_s`` gives a failure with
reason ``timeout``, a child that dies gives ``crashed``; either names the object and the reason,
and the caller goes on with the next object. Used by `datagen prepare` and by the job workers.

    p = process_isolated(entry, cfg, root, timeout_s=300)   # a ProcessedObject, never raises
    p.ok, p.reason, p.message

Ctrl-C ends a child at once and silently (`datagen._interrupt`, policy "die"); ``children``
(`Children`) lets the caller end the children of its running calls itself, when only it was
interrupted.

Before any child starts, the file is read and hashed here: a missing file (``missing_file``), one
that is not a regular file inside the source root, or one whose bytes are not the manifest's
sha256 (``sha256_mismatch``) is a failure, never a cache hit under the manifest's hash; a finished
cache entry of those bytes is returned without starting a child.
"""

from __future__ import annotations

import hashlib
import multiprocessing as mp
import threading
from pathlib import Path
from typing import Callable

from datagen._interrupt import on_sigint, sigint_blocked

from .cache import cache_root
from .config import ProcessConfig
from .errors import ObjectError, Reason
from .manifest import ManifestEntry
from .process import ProcessedObject, as_object, cached, load_processed, process_object

__all__ = ["Children", "process_isolated"]

#: ``step(ref, cfg, root, expected_sha256) -> ProcessedObject``: what the child runs
Step = Callable[..., ProcessedObject]


class Children:
    """The child processes of the `process_isolated` calls given this object (from any thread).
    `stop` kills those running and any started later, e.g. when the caller is interrupted: their
    calls then return ``crashed`` failures, and a killed child leaves at most a temp dir in the
    cache (`cache.clean_stale_temp`)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._procs: set = set()
        self._stopped = False

    def _add(self, proc) -> None:
        with self._lock:
            self._procs.add(proc)
            if self._stopped:
                proc.kill()

    def _discard(self, proc) -> None:
        with self._lock:
            self._procs.discard(proc)

    def stop(self) -> None:
        with self._lock:
            self._stopped = True
            for proc in self._procs:
                proc.kill()


def _child(conn, step: Step, entry: ManifestEntry, cfg_dict: dict, root: str) -> None:
    """Process one object; always sends (status, reason, message, entry, cache_hit) unless the
    process dies (a Ctrl-C ends it at once, without a traceback)."""
    on_sigint("die")
    try:
        try:
            p = step(entry.ref(), ProcessConfig.from_dict(cfg_dict), root, entry.sha256)
            msg = (p.status, p.reason, p.message, str(p.entry) if p.entry else "", p.cache_hit)
        except ObjectError as exc:
            msg = ("failed", exc.reason.value, str(exc), "", False)
    except Exception as exc:  # noqa: BLE001 - e.g. an unwritable cache: a cause, not a crash
        msg = ("failed", "error", f"{entry.id}: {type(exc).__name__}: {exc}", "", False)
    conn.send(msg)
    conn.close()


def _failed(entry: ManifestEntry, reason: str, message: str) -> ProcessedObject:
    return ProcessedObject(entry.id, "failed", reason, message, mesh_sha256=entry.sha256)


def process_isolated(entry: ManifestEntry, cfg: ProcessConfig, root: str | Path | None, timeout_s: float, *,
                     remedy: str = "raise the time limit and rerun", step: Step = process_object,
                     children: Children | None = None) -> ProcessedObject:
    """The processed object of manifest ``entry`` (see the module docstring), labelled with the
    entry's id: from the cache under ``root`` if there, else built by ``step`` (default
    `process_object`; a module-level function, so the child can import it) in a fresh process
    that is killed after ``timeout_s`` seconds (``remedy``: the caller's advice in that message;
    ``children``: where the process is registered while it runs). Never raises for a bad, slow
    or crashing object."""
    try:
        ref = entry.ref()
        sha = hashlib.sha256(ref.read_bytes()).hexdigest()
        if sha != entry.sha256:
            return _failed(entry, Reason.SHA_MISMATCH.value, f"{entry.id}: {Reason.SHA_MISMATCH.value}: file sha256 "
                           f"{sha[:12]}... != manifest {entry.sha256[:12]}...; the file changed since the manifest "
                           "was built: rebuild it")
        hit = cached(ref, sha, cfg, root)
    except ObjectError as exc:
        return _failed(entry, exc.reason.value, str(exc))
    except OSError as exc:
        return _failed(entry, "error", f"{entry.id}: {type(exc).__name__}: {exc}")
    if hit is not None:
        return hit
    ctx = mp.get_context("spawn")  # no fork: the parent may hold threads (torch, Ray)
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, step, entry, cfg.to_dict(), str(cache_root(root))), daemon=True)
    with sigint_blocked():  # until the child has set its Ctrl-C policy
        proc.start()
    child.close()
    if children is not None:
        children._add(proc)
    try:
        if not parent.poll(timeout_s):
            return _failed(entry, Reason.TIMEOUT.value,
                           f"{entry.id}: processing exceeded {timeout_s:g} s and was killed ({remedy})")
        try:
            status, reason, message, path, cache_hit = parent.recv()
        except EOFError:
            proc.join(5)
            return _failed(entry, Reason.CRASHED.value, f"{entry.id}: the processing process died "
                           f"(exit code {proc.exitcode})")
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join(5)
        parent.close()
        if children is not None:
            children._discard(proc)
    if status != "ok":
        out = _failed(entry, reason, message)
        return out if not path else ProcessedObject(entry.id, "failed", reason, message, entry=Path(path),
                                                    mesh_sha256=entry.sha256, cache_hit=cache_hit)
    return as_object(load_processed(Path(path), cache_hit=cache_hit), ref)
