"""Batch processing of a manifest: every object ends as "ok" or a recorded failure reason.

Each object is processed in its own process with a time limit (`isolate.process_isolated`): one
that hangs or crashes CoACD is a ``timeout`` or ``crashed`` failure naming it, and the others are
processed all the same. A cache hit is answered by an already running worker (a read and a hash).
"""

from __future__ import annotations

import collections
import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from datagen._atomic import atomic_write_text

from .cache import cache_root, clean_stale_temp
from .config import ProcessConfig
from .isolate import Children, Step, process_isolated
from .manifest import ManifestEntry, load_manifest
from .process import ProcessedObject, process_object

__all__ = ["DEFAULT_TIMEOUT_S", "prepare", "summarize"]

DEFAULT_TIMEOUT_S = 600.0  #: per-object processing limit (CoACD takes 6-120 s on a typical object)


def _row(entry: ManifestEntry, r: ProcessedObject) -> dict:
    return {"id": entry.id, "status": r.status, "reason": r.reason, "message": r.message,
            "entry": str(r.entry) if r.entry else "", "cache_hit": r.cache_hit,
            "pieces": len(r.piece_volumes), "timings": r.timings}


def prepare(manifest: str | Path | list[ManifestEntry], cfg: ProcessConfig | None = None,
            root: str | Path | None = None, workers: int = 1, progress: bool = True,
            limit: int | None = None, timeout_s: float = DEFAULT_TIMEOUT_S, *,
            step: Step = process_object) -> list[dict]:
    """Process every manifest object (cache hits are cheap), each in its own process killed after
    ``timeout_s`` seconds, ``workers`` at a time. Returns one status dict per object, in manifest
    order: id, status ('ok'/'failed'), reason, message, entry, cache_hit, pieces, timings
    (seconds per stage). Temp dirs left by killed runs (> 6 h old) are removed first. ``step``:
    what each process runs (`process_object`; tests inject a slow or crashing one). Interrupted
    (KeyboardInterrupt), it kills the processes still running and re-raises: the objects finished
    so far are in the cache, so the same call again processes only the others."""
    if not timeout_s > 0:
        raise ValueError(f"the per-object time limit must be > 0 seconds, got {timeout_s}")
    entries = load_manifest(manifest) if isinstance(manifest, (str, Path)) else list(manifest)
    entries = entries[:limit] if limit is not None else entries
    cfg = cfg or ProcessConfig()
    clean_stale_temp(cache_root(root))  # temp dirs of killed runs older than 6 h
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(entries), desc="prepare", unit="obj")

    children = Children()

    def one(entry: ManifestEntry) -> dict:
        r = process_isolated(entry, cfg, root, timeout_s, step=step,
                             remedy="raise `datagen prepare --timeout` and rerun", children=children)
        bar and bar.update()
        return _row(entry, r)

    # threads only wait: each object's work is in its own process
    pool = ThreadPoolExecutor(max_workers=max(1, workers))
    try:
        out = list(pool.map(one, entries))
    except BaseException:  # Ctrl-C: end the objects in progress instead of waiting for them
        pool.shutdown(wait=False, cancel_futures=True)
        children.stop()
        raise
    finally:
        pool.shutdown(wait=True)
        bar and bar.close()
    return out


SHOWN_FAILURES = 10  #: failed objects `summarize` names one per line


def summarize(results: list[dict], results_path: str | Path | None = None) -> str:
    """Counts of ok, cache hits and failures by reason on the first line; then each failed
    object (its message, up to `SHOWN_FAILURES`) and where the full list is (``results_path``,
    the ``--results`` file) or how to get it."""
    failed = [r for r in results if r["status"] != "ok"]
    reasons = collections.Counter(r["reason"] for r in failed)
    ok = sum(r["status"] == "ok" for r in results)
    hits = sum(bool(r["cache_hit"]) for r in results)
    fails = ", ".join(f"{k}: {v}" for k, v in sorted(reasons.items())) or "none"
    lines = [f"{len(results)} objects: {ok} ok, {hits} cache hits; failures: {fails}"]
    lines += [f"  {r['message'] or r['id'] + ': ' + r['reason']}" for r in failed[:SHOWN_FAILURES]]
    if len(failed) > SHOWN_FAILURES:
        lines.append(f"  ... and {len(failed) - SHOWN_FAILURES} more")
    if failed:
        lines.append(f"every object's status: {results_path}" if results_path else
                     "every object's status, one JSON line each: rerun with --results FILE (cache hits are cheap)")
    return "\n".join(lines)


def write_results(results: list[dict], path: str | Path) -> None:
    atomic_write_text(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in results))
