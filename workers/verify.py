"""``datagen verify JOB_DIR``: every file the ledger vouches for, checked to its sha256.

`datagen status` checks sizes and footer row counts (cheap: no data read); this reads every
listed file whole and compares its sha256 with the ledger's, and checks that the processed
objects the rows name are in the job (`datagen.io.integrity.audit`, deep). What it finds is what
a rerun of the job repairs: a shard that does not match is redone with its own seed, so with the
same rows.
"""

from __future__ import annotations

import time
from pathlib import Path

from datagen.io.integrity import ShardError, check_text, read_ledger
from datagen.io.layout import LEDGER_DIR, MANIFEST, MANIFEST_RECORD

from .job import JobDir

__all__ = ["format_verify", "verify_job"]


def verify_job(path: str | Path) -> dict:
    """``{"job", "shards_finished", "files_checked", "problems": {shard: line}, "unrecorded": [shard],
    "seconds"}`` (`JobDir.audit`, deep); raises `JobError` for an unreadable job.json."""
    t0 = time.perf_counter()
    job = JobDir(path)
    job.read_job()  # names job.json and the remedy when it is damaged
    found = job.audit(deep=True)
    return {"job": str(job.path), "shards_finished": len(found.finished) + len(found.problems),
            "files_checked": found.checked_files + (job.manifest_record_path.is_file()),
            "problems": dict(sorted(found.problems.items())), "manifest": _manifest_problem(job),
            "unrecorded": sorted(found.unrecorded), "seconds": round(time.perf_counter() - t0, 3)}


def _manifest_problem(job: JobDir) -> str | None:
    """Why manifest.jsonl does not match ``ledger/manifest.json``, or None (also for a job made
    before the record existed)."""
    if not job.manifest_record_path.is_file():
        return None
    try:
        record = read_ledger(job.manifest_record_path)
    except ShardError as exc:
        return f"{LEDGER_DIR}/{MANIFEST_RECORD}: {exc.reason}"
    why = check_text(job.manifest_path, record)
    return f"{MANIFEST}: {why}" if why else None


def format_verify(v: dict) -> str:
    n = len(v["problems"]) + bool(v["manifest"])
    lines = [f"job {v['job']}: {v['shards_finished']} finished shards, {v['files_checked']} files checked to their "
             f"sha256 in {v['seconds']:.1f} s: " + ("all match the ledger" if not n else f"{n} do not")]
    if v["manifest"]:
        lines.append(f"  {v['manifest']}")
    for i, why in v["problems"].items():
        lines.append(f"  shard {i}: {why}")
    if v["unrecorded"]:
        lines.append(f"  {len(v['unrecorded'])} shard(s) were written before the ledger recorded checksums "
                     f"(shards {', '.join(map(str, v['unrecorded'][:10]))}): only their page checksums, if any, "
                     "are checked when they are read")
    if v["problems"]:
        lines.append(f"repair: datagen run --resume --out {v['job']} (redoes these shards with their own seeds: "
                     "the same rows)")
    if v["manifest"]:
        lines.append(f"repair: datagen run --resume --out {v['job']} builds the manifest again from the job's source "
                     "and keeps it if it matches the ledger's sha256; otherwise restore it from a copy")
    return "\n".join(lines)
