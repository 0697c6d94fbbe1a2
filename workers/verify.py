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
            "files_checked": found.checked_files, "problems": dict(sorted(found.problems.items())),
            "unrecorded": sorted(found.unrecorded), "seconds": round(time.perf_counter() - t0, 3)}


def format_verify(v: dict) -> str:
    n = len(v["problems"])
    lines = [f"job {v['job']}: {v['shards_finished']} finished shards, {v['files_checked']} files checked to their "
             f"sha256 in {v['seconds']:.1f} s: " + ("all match the ledger" if not n else f"{n} do not")]
    for i, why in v["problems"].items():
        lines.append(f"  shard {i}: {why}")
    if v["unrecorded"]:
        lines.append(f"  {len(v['unrecorded'])} shard(s) were written before the ledger recorded checksums "
                     f"(shards {', '.join(map(str, v['unrecorded'][:10]))}): only their page checksums, if any, "
                     "are checked when they are read")
    if n:
        lines.append(f"repair: datagen run --resume --out {v['job']} (redoes these shards with their own seeds: "
                     "the same rows)")
    return "\n".join(lines)
