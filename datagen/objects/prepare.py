"""Batch processing of a manifest: every object ends as "ok" or a recorded failure reason."""

from __future__ import annotations

import collections
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from .cache import cache_root, clean_stale_temp
from .config import ProcessConfig
from .manifest import ManifestEntry, load_manifest
from .process import ProcessedObject, process_object

__all__ = ["prepare", "summarize"]


def _one(args) -> dict:
    entry, cfg, root = args
    r: ProcessedObject = process_object(entry.ref(), cfg, root, entry.sha256)
    return {"id": entry.id, "status": r.status, "reason": r.reason, "message": r.message,
            "entry": str(r.entry) if r.entry else "", "cache_hit": r.cache_hit,
            "pieces": len(r.piece_volumes), "timings": r.timings}


def prepare(manifest: str | Path | list[ManifestEntry], cfg: ProcessConfig | None = None,
            root: str | Path | None = None, workers: int = 1, progress: bool = True,
            limit: int | None = None) -> list[dict]:
    """Process every manifest object (cache hits are free). Returns one status dict per object,
    in manifest order: id, status ('ok'/'failed'), reason, message, entry, cache_hit, pieces,
    timings (seconds per stage). Temp dirs left by killed runs (> 6 h old) are removed first."""
    entries = load_manifest(manifest) if isinstance(manifest, (str, Path)) else list(manifest)
    entries = entries[:limit] if limit is not None else entries
    cfg = cfg or ProcessConfig()
    clean_stale_temp(cache_root(root))  # temp dirs of killed runs older than 6 h
    jobs = [(e, cfg, str(root) if root else None) for e in entries]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(jobs), desc="prepare", unit="obj")
    out = []
    if workers <= 1:
        for job in jobs:
            out.append(_one(job))
            bar and bar.update()
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for res in pool.map(_one, jobs):
                out.append(res)
                bar and bar.update()
    bar and bar.close()
    return out


def summarize(results: list[dict]) -> str:
    """One line: counts of ok, cache hits and failures by reason."""
    reasons = collections.Counter(r["reason"] for r in results if r["status"] != "ok")
    ok = sum(r["status"] == "ok" for r in results)
    hits = sum(bool(r["cache_hit"]) for r in results)
    fails = ", ".join(f"{k}: {v}" for k, v in sorted(reasons.items())) or "none"
    return f"{len(results)} objects: {ok} ok, {hits} cache hits; failures: {fails}"


def write_results(results: list[dict], path: str | Path) -> None:
    Path(path).write_text("".join(json.dumps(r, sort_keys=True) + "\n" for r in results))
