"""Object processing in a separate process with a time limit.

CoACD is native code: on a bad mesh it can run for hours or crash the interpreter. Processing an
object in a child process bounds both: a child killed after ``timeout_s`` gives a failure with
reason ``timeout``, a child that dies gives ``crashed``; either names the object and the reason,
and the caller goes on with the next object. Used by `datagen prepare` and by the job workers.
The children are long-lived worker interpreters (`isolated_worker`), one object at a time each:
started once, not once per object, and replaced when one is killed or dies.

    p = process_isolated(entry, cfg, root, timeout_s=300)   # a ProcessedObject, never raises
    p.ok, p.reason, p.message

Ctrl-C ends a child at once and silently (`datagen._interrupt`, policy "die"); ``children``
(`Children`) lets the caller end the children of its running calls itself, when only it was
interrupted.

Only the path is checked here (inside its source root). Reading and hashing the file belong to
the time-limited step in the child (`process_object`): a missing file (``missing_file``), one that
is not a regular file or is over ``ProcessConfig.max_mesh_bytes`` (refused unread), or one whose
bytes are not the manifest's sha256 (``sha256_mismatch``) is a failure, never a cache hit under the
manifest's hash; a slow read (a hung network file system) is a ``timeout`` like a slow CoACD. A
cache hit costs the child a read, a hash and a reply (milliseconds once a worker is running).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Callable

from . import isolated_worker
from .cache import cache_root
from .config import ProcessConfig
from .errors import ObjectError, Reason
from .manifest import ManifestEntry
from .process import ProcessedObject, as_object, load_processed, process_object

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


def _reply(step: Step, entry: ManifestEntry, cfg_dict: dict, root: str) -> tuple:
    """Process one object (in a worker); ``(status, reason, message, entry, cache_hit)``, never
    raises for what the object or the cache does."""
    try:
        try:
            p = step(entry.ref(), ProcessConfig.from_dict(cfg_dict), root, entry.sha256)
            return (p.status, p.reason, p.message, str(p.entry) if p.entry else "", p.cache_hit)
        except ObjectError as exc:
            return ("failed", exc.reason.value, str(exc), "", False)
    except Exception as exc:  # noqa: BLE001 - e.g. an unwritable cache: a cause, not a crash
        return ("failed", "error", f"{entry.id}: {type(exc).__name__}: {' '.join(str(exc).split())}", "", False)


def _release(worker: isolated_worker.IsolatedWorker, children: Children | None, kill: bool) -> None:
    if children is not None:
        children._discard(worker)
    if kill:
        worker.close()
    else:
        isolated_worker.give(worker)


def _failed(entry: ManifestEntry, reason: str, message: str) -> ProcessedObject:
    return ProcessedObject(entry.id, "failed", reason, message, mesh_sha256=entry.sha256)


def process_isolated(entry: ManifestEntry, cfg: ProcessConfig, root: str | Path | None, timeout_s: float, *,
                     remedy: str = "raise the time limit and rerun", step: Step = process_object,
                     children: Children | None = None) -> ProcessedObject:
    """The processed object of manifest ``entry`` (see the module docstring), labelled with the
    entry's id: from the cache under ``root`` if there, else built by ``step`` (default
    `process_object`; a module-level function, so the worker can import it) in a worker process
    that is killed after ``timeout_s`` seconds (``remedy``: the caller's advice in that message;
    ``children``: where the worker is registered while it runs). Never raises for a bad, slow
    or crashing object."""
    try:
        ref = entry.ref()  # inside its source root (the path only: no byte is read here)
    except ObjectError as exc:
        return _failed(entry, exc.reason.value, str(exc))
    worker = None
    try:
        for _ in range(2):  # an idle worker can have died since (Ctrl-C, OOM): one fresh retry
            worker = isolated_worker.take()
            if children is not None:
                children._add(worker)
            try:
                worker.wait_ready()  # its start (imports) is not the object's time
                worker.submit((_reply, (step, entry, cfg.to_dict(), str(cache_root(root)))))
                break
            except (BrokenPipeError, ConnectionResetError, EOFError, TimeoutError):
                _release(worker, children, kill=True)
                worker = None
        if worker is None:
            return _failed(entry, Reason.CRASHED.value, f"{entry.id}: no processing worker could be started")
        try:
            kind, reply = worker.result(timeout_s)
        except TimeoutError:
            _release(worker, children, kill=True)
            return _failed(entry, Reason.TIMEOUT.value,
                           f"{entry.id}: processing exceeded {timeout_s:g} s and was killed ({remedy})")
        except (EOFError, ConnectionResetError):
            code = worker.exitcode()  # it is exiting: its own code, not the kill's
            _release(worker, children, kill=True)
            return _failed(entry, Reason.CRASHED.value, f"{entry.id}: the processing process died "
                           f"(exit code {code})")
    except OSError as exc:  # the worker could not be started (no memory, no processes left)
        if worker is not None:
            _release(worker, children, kill=True)
        return _failed(entry, Reason.CRASHED.value, f"{entry.id}: cannot start a processing process: "
                       f"{type(exc).__name__}: {exc}")
    _release(worker, children, kill=False)
    if kind != "ok":
        return _failed(entry, "error", f"{entry.id}: the processing worker cannot load its task ({reply}); "
                       "the step must be importable by module (not defined in __main__)")
    status, reason, message, path, cache_hit = reply
    if status != "ok":
        out = _failed(entry, reason, message)
        return out if not path else ProcessedObject(entry.id, "failed", reason, message, entry=Path(path),
                                                    mesh_sha256=entry.sha256, cache_hit=cache_hit)
    return as_object(load_processed(Path(path), cache_hit=cache_hit), ref)
