"""Reading a job's shards: an Arrow dataset, a table, and a torch Dataset for learning.

Only finished shards (those with a ledger entry) are read, so a running or interrupted job
shows a consistent subset. The files are plain Parquet: pyarrow.dataset, pandas, DuckDB or
Hugging Face datasets read ``JOB/shards/*.parquet`` without this module.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from schemas import SchemaError, check_version

from . import layout

__all__ = ["POSE_COLUMNS", "joint_names", "open_dataset", "read_job", "shard_paths"]

POSE_COLUMNS = ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")


def shard_paths(job_dir: str | Path) -> list[Path]:
    """Finished shard files of a job, in shard order (raises FileNotFoundError if not a job).
    A finished shard without rows (all its objects failed) has no file."""
    job = Path(job_dir)
    if not (job / layout.JOB_JSON).is_file():
        raise FileNotFoundError(f"{job} is not a datagen job directory (no {layout.JOB_JSON})")
    out = []
    for led in sorted((job / layout.LEDGER_DIR).glob("part-*.json")):
        p = job / layout.SHARDS_DIR / f"{led.stem}.parquet"
        if p.is_file():
            out.append(p)
    return out


def open_dataset(job_dir: str | Path) -> "pyarrow.dataset.Dataset":  # noqa: F821
    """A ``pyarrow.dataset`` over the finished shards (schema ``evaluated`` checked)."""
    import pyarrow.dataset as ds  # here, not at import: it pulls in pandas (~0.2 s for every shard worker)

    paths = shard_paths(job_dir)
    if not paths:
        raise FileNotFoundError(f"{job_dir}: no grasp rows yet (no finished shard with rows)")
    schemas = [pq.read_schema(p) for p in paths]  # footers only: cheap, and every shard is checked
    for p, sch in zip(paths, schemas):
        check_version(sch, "evaluated", where=str(p))
    return ds.dataset([str(p) for p in paths], format="parquet", schema=schemas[0])


def read_job(job_dir: str | Path, columns: list[str] | None = None, only_success: bool = False) -> pa.Table:
    """The job's rows as one table (``object_path`` stays relative to ``job_dir``)."""
    flt = pc.field("success") == True if only_success else None  # noqa: E712 - an Arrow expression
    return open_dataset(job_dir).to_table(columns=columns, filter=flt)


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
