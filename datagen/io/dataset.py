"""Reading a job's shards: an Arrow dataset, a table, and a torch Dataset for learning.

Only finished shards (those with a ledger entry) are read, so a running or interrupted job
shows a consistent subset; each is checked against what its entry records (`integrity`). The
files are plain Parquet: pyarrow.dataset, pandas, DuckDB or Hugging Face datasets read
``JOB/shards/*.parquet`` without this module.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from schemas import SchemaError, check_version

from . import layout
from .integrity import ShardError, audit, redo_remedy

__all__ = ["POSE_COLUMNS", "joint_names", "open_dataset", "read_job", "shard_paths"]

POSE_COLUMNS = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


def shard_paths(job_dir: str | Path) -> list[Path]:
    """Finished shard files of a job, in shard order (raises FileNotFoundError if not a job).
    A finished shard without rows (all its objects failed) has no file. Each file is checked
    against its ledger entry (size and footer row count: `integrity.audit`); the first that does
    not match raises `ShardError` naming it."""
    job = Path(job_dir)
    if not (job / layout.JOB_JSON).is_file():
        raise FileNotFoundError(f"{job} is not a datagen job directory (no {layout.JOB_JSON})")
    found = audit(job)
    if found.problems:
        i, why = min(found.problems.items())
        path, _, reason = why.partition(": ")
        more = (f"; and {len(found.problems) - 1} more shard(s) (`datagen verify {job}` lists them)"
                if len(found.problems) > 1 else "")
        raise ShardError(job / path, reason + more, redo_remedy(job))
    return list(found.shard_files(job).values())


def _format():
    import pyarrow.dataset as ds  # here, not at import: it pulls in pandas (~0.2 s for every shard worker)

    return ds.ParquetFileFormat(default_fragment_scan_options=ds.ParquetFragmentScanOptions(
        page_checksum_verification=True))


def open_dataset(job_dir: str | Path) -> "pyarrow.dataset.Dataset":  # noqa: F821
    """A ``pyarrow.dataset`` over the finished shards (each checked against the ledger by
    `shard_paths`, schema ``evaluated`` checked, page checksums verified as it is scanned; a
    damaged page then raises an OSError that pyarrow does not attribute to a file: `read_job`
    names it)."""
    import pyarrow.dataset as ds

    paths = shard_paths(job_dir)
    if not paths:
        raise FileNotFoundError(f"{job_dir}: no grasp rows yet (no finished shard with rows)")
    schemas = []
    for p in paths:  # footers only: cheap, and every shard is checked
        try:
            schemas.append(pq.read_schema(p))
        except (OSError, pa.ArrowException) as exc:
            raise ShardError(p, f"its Parquet footer cannot be read ({' '.join(str(exc).split())})",
                             redo_remedy(job_dir)) from None
        check_version(schemas[-1], "evaluated", where=str(p))
    return ds.dataset([str(p) for p in paths], format=_format(), schema=schemas[0])


def read_job(job_dir: str | Path, columns: list[str] | None = None, only_success: bool = False) -> pa.Table:
    """The job's rows as one table (``object_path`` stays relative to ``job_dir``). Every shard
    is checked against the ledger and read with its page checksums verified: a damaged one
    raises `ShardError` naming the file (a rerun of the job redoes it)."""
    flt = pc.field("success") == True if only_success else None  # noqa: E712 - an Arrow expression
    dataset = open_dataset(job_dir)
    parts = []
    for frag in dataset.get_fragments():
        try:
            parts.append(frag.to_table(schema=dataset.schema, columns=columns, filter=flt))
        except (OSError, pa.ArrowException) as exc:
            raise ShardError(frag.path, f"damaged: {' '.join(str(exc).split())}", redo_remedy(job_dir)) from None
    return pa.concat_tables(parts) if parts else dataset.schema.empty_table()


def joint_names(job_dir: str | Path) -> list[str]:
    """Joint names of the qpos columns after the 7 root entries (every row also carries them in
    its ``joint_names`` column; this reads the file metadata, which older shards have too)."""
    paths = shard_paths(job_dir)
    if not paths:
        raise FileNotFoundError(f"{job_dir}: no grasp rows yet (no finished shard with rows)")
    meta = pq.read_schema(paths[0]).metadata or {}
    if b"datagen.joint_names" not in meta:
        raise SchemaError(f"{paths[0]}: no datagen.joint_names in the file metadata")
    return json.loads(meta[b"datagen.joint_names"])
