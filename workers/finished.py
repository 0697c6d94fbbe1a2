"""What a job has finished: its ledger's shards, those a rerun redoes, and the merged failures.

A shard is finished once its ledger entry is written (last); a rerun redoes a shard whose files no
longer match that entry, and with ``--retry-failed`` a finished shard with failures a rerun may
fix (any reason but `FINAL_REASONS`, which an object's bytes decide).
"""

from __future__ import annotations

import pyarrow as pa

from schemas import arrow_schema

from datagen.io import integrity

from .job import JobDir
from .shard import write_table_atomic

__all__ = ["FINAL_REASONS", "finished_or_redo", "merge_failures", "retryable_shards"]

# failure reasons decided by an object's bytes: cached with the object, so a retry cannot change
# them; every other failure (timeout, crashed, error, missing_file, ...) is retried by
# `run_job(retry_failed=True)`
FINAL_REASONS = frozenset({"unreadable_mesh", "empty_mesh", "non_finite_vertices", "huge_coordinates", "too_many_faces",
                           "degenerate_mesh", "coacd_failed", "coacd_no_parts", "surface_failed", "mjcf_failed"})


def merge_failures(job: JobDir, done: dict | None = None) -> pa.Table:
    """Concatenate the manifest's failures and those of the finished shards (``done``, default
    `JobDir.finished`; parts of unfinished shards are not theirs yet) into ``failures.parquet``
    (atomically). A part that cannot be read is a `ShardError` naming it."""
    schema = arrow_schema("failures")
    done = job.finished() if done is None else done
    files = ([job.manifest_failures_path] if job.manifest_failures_path.is_file() else [])
    files += [job.shard_failures_path(i) for i in sorted(done) if job.shard_failures_path(i).is_file()]
    remedy = integrity.redo_remedy(job.path)
    parts = [integrity.read_parquet(p, remedy=remedy) for p in files]
    table = pa.concat_tables([p.cast(schema) for p in parts]) if parts else schema.empty_table()
    write_table_atomic(table, job.failures_path)
    return table


def retryable_shards(job: JobDir, done: dict) -> list[int]:
    """Finished shards with a failure a rerun may fix (any reason outside `FINAL_REASONS`)."""
    out = []
    for i in sorted(done):
        fp = job.shard_failures_path(i)
        if fp.is_file() and any(r not in FINAL_REASONS for r in integrity.read_parquet(fp, ["reason"])["reason"]
                                .to_pylist()):
            out.append(i)
    return out


def finished_or_redo(job: JobDir, log) -> dict[int, dict]:
    """The finished shards whose files match their ledger entry to the sha256 (`JobDir.audit`,
    deep); a shard whose file is missing, truncated or changed, or whose entry cannot be read,
    loses its entry (said, with why) and is redone: its seed is fixed, so are its rows."""
    found = job.audit(deep=True)
    for i, why in sorted(found.problems.items()):
        log(f"shard {i}: {why}; redoing it")
        job.ledger_path(i).unlink(missing_ok=True)
    return found.finished
