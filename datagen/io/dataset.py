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
from .integrity import ShardError, audit, read_parquet, redo_remedy

__all__ = ["POSE_COLUMNS", "joint_names", "observation_paths", "open_dataset", "read_job", "read_observations",
           "shard_paths"]

POSE_COLUMNS = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


def _audited(job_dir: str | Path):
    """`integrity.audit` of the job (raises FileNotFoundError if not a job, `ShardError` naming
    the first file that does not match its ledger entry)."""
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
    return found


def shard_paths(job_dir: str | Path) -> list[Path]:
    """Finished shard files of a job, in shard order (raises FileNotFoundError if not a job).
    A finished shard without rows (all its objects failed) has no file. Each file is checked
    against its ledger entry (size and footer row count: `integrity.audit`); the first that does
    not match raises `ShardError` naming it."""
    return list(_audited(job_dir).shard_files(job_dir).values())


def observation_paths(job_dir: str | Path) -> list[Path]:
    """Observation files of the finished shards (``observations/part-NNNNN.parquet``), in shard
    order, each checked against its ledger entry as `shard_paths` checks the shards. A job made
    with ``observations`` off, or before they existed, has none."""
    return list(_audited(job_dir).observation_files(job_dir).values())


def read_observations(job_dir: str | Path, columns: list[str] | None = None, split: str | None = None) -> pa.Table:
    """The job's object observations (schema ``observations``: one row per object and scale,
    joinable to `read_job`'s rows on ``object_id`` and ``object_scale_m``), every file checked
    against the ledger, its schema version and its page checksums; ``split``: only that split's
    objects. FileNotFoundError when the job has none."""
    paths = observation_paths(job_dir)
    if not paths:
        raise FileNotFoundError(f"{job_dir}: no object observations (a job with `observations: {{points: 0, "
                                "views: 0}}`, made before they existed, or with no finished shard yet)")
    flt = pc.field("split") == split if split is not None else None
    parts = []
    for p in paths:
        try:
            check_version(pq.read_schema(p), "observations", where=str(p))
        except (OSError, pa.ArrowException) as exc:
            raise ShardError(p, f"its Parquet footer cannot be read ({' '.join(str(exc).split())})",
                             redo_remedy(job_dir)) from None
        parts.append(read_parquet(p, columns=columns, filter=flt, remedy=redo_remedy(job_dir)))
    return pa.concat_tables(parts)


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
    raises `ShardError` naming the file (a rerun of the job redoes it); a column the schema does
    not have raises ValueError naming it."""
    flt = pc.field("success") == True if only_success else None  # noqa: E712 - an Arrow expression
    dataset = open_dataset(job_dir)
    unknown = [c for c in columns or () if c not in dataset.schema.names]
    if unknown:
        raise ValueError(f"read_job: no column {', '.join(map(repr, unknown))} in {job_dir}'s rows "
                         f"(schema `evaluated`: schemas/; e.g. {', '.join(dataset.schema.names[:6])}, ...)")
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
