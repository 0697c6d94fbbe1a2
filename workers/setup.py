"""A job directory made ready to run: the output and cache checked, the manifest, the hand pinned.

Everything that is refused here is refused before any object is processed; a job directory the
driver created and could not start is removed again (`discard_new_job`).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import pyarrow as pa

from datagen._atomic import atomic_write_text
from datagen.io.integrity import ShardError, check_text, read_ledger, text_record
from datagen.io.layout import MANIFEST
from schemas import arrow_schema

from .job import JobConfig, JobDir, JobError, writing
from .shard import _failure, write_table_atomic

__all__ = ["check_cache", "check_out", "discard_new_job", "pin_job_hand", "prepare_manifest"]


def prepare_manifest(job: JobDir, cfg: JobConfig) -> list:
    """The job's manifest slice: read back when present (resume), else built or cut from
    ``cfg.manifest`` and written atomically, with its size, line count and sha256 in
    ``ledger/manifest.json``. Objects of the source that cannot be manifest entries become rows
    of ``failures/manifest.parquet`` (stage ``manifest``)."""
    if job.manifest_path.is_file() or _manifest_record(job) is not None:
        return _read_back_manifest(job, cfg)
    entries, rejected = _build_entries(cfg)
    rows: list[dict] = []
    for r in rejected:  # shard -1: before any shard
        _failure(rows, -1, r.id, "manifest", r.reason, r.message)
    write_table_atomic(pa.Table.from_pylist(rows, schema=arrow_schema("failures")), job.manifest_failures_path)
    if not entries:
        raise JobError(f"job {job.path}: the manifest is empty (source {cfg.source!r}, manifest {cfg.manifest!r})"
                       + "".join(f"\n  {r.message}" for r in rejected[:5]))
    _write_manifest(job, entries)
    return entries


def _build_entries(cfg: JobConfig) -> tuple[list, list]:
    """The manifest entries ``cfg`` names and the source's rejected objects."""
    from datagen.objects.manifest import build_manifest, load_manifest

    rejected: list = []
    if cfg.manifest:
        entries = load_manifest(cfg.manifest)[: cfg.count]
        if len(entries) < cfg.count:
            print(f"warning: manifest {cfg.manifest} has {len(entries)} objects, fewer than count {cfg.count}",
                  file=sys.stderr)
    else:
        entries = build_manifest(cfg.source, cfg.count, cfg.scales, cfg.test_fraction, rejected=rejected,
                                 max_mesh_bytes=cfg.recipes()[0].process.max_mesh_bytes)
    return entries, rejected


def _write_manifest(job: JobDir, entries: list) -> None:
    from datagen.objects.manifest import manifest_text, write_manifest

    with writing(job.manifest_path, "the job's manifest"):
        write_manifest(entries, job.manifest_path)
    with writing(job.manifest_record_path, "the manifest's ledger record"):
        atomic_write_text(job.manifest_record_path, json.dumps(text_record(manifest_text(entries)), indent=1))


def _manifest_record(job: JobDir) -> dict | None:
    """``ledger/manifest.json`` (None for a job made before it was written)."""
    if not job.manifest_record_path.is_file():
        return None
    try:
        return read_ledger(job.manifest_record_path)
    except ShardError as exc:
        raise JobError(f"job {job.path}: {exc}") from None


def _read_back_manifest(job: JobDir, cfg: JobConfig) -> list:
    """A resumed job's manifest, checked against its record. A damaged one is built again from
    the job's source and kept when it matches the record (the same objects, so the same shards);
    otherwise `JobError` naming the file and the reason."""
    from datagen.objects.errors import ManifestError
    from datagen.objects.manifest import load_manifest, manifest_text

    record = _manifest_record(job)
    why = check_text(job.manifest_path, record) if record is not None else None
    if why is None:
        try:
            return load_manifest(job.manifest_path, check_paths=False)
        except ManifestError as exc:
            why = f"no longer loads ({exc})"
    if record is not None:
        entries, _ = _build_entries(cfg)
        if text_record(manifest_text(entries)) == record:
            _write_manifest(job, entries)
            print(f"job {job.path}: {MANIFEST} {why}; built again from the job's source, it matches the sha256 the "
                  "ledger recorded: resuming", file=sys.stderr)
            return entries
    raise JobError(f"job {job.path}: {MANIFEST} {why}, and the job's source does not give it again: it no longer "
                   "says which objects the shards were made from; restore it from a copy, or start the job in a new "
                   "--out") from None


def pin_job_hand(job: JobDir, spec) -> Path:
    """Keep the job's hand in the job directory (``hands/<name>.yaml``, `datagen.hands.pin`): its
    shards load it from there and so does every reader of its rows, wherever the job is moved. A
    resumed job whose hand spec or asset files changed since it was created is refused (JobError
    naming the file): its rows would mix two hands."""
    from datagen.hands import HandSpecError, pin_hand

    try:
        return pin_hand(spec, job.path)
    except HandSpecError as exc:
        raise JobError(f"job {job.path}: {exc}") from None


def check_out(path: Path) -> None:
    """A usable job directory: not a file, and writable (JobError naming the problem)."""
    if path.exists() and not path.is_dir():
        raise JobError(f"--out {path} is an existing file, not a job directory; choose another --out")
    probe = path
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise JobError(f"--out {path}: cannot write in {probe} (permission denied); choose another --out")


def check_cache(cache: str | None) -> None:
    """The objects cache root exists or can be made, and is writable (JobError otherwise)."""
    from datagen.objects.cache import cache_root

    root = cache_root(cache or os.environ.get("DATAGEN_CACHE") or None)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise JobError(f"objects cache {root}: cannot create it ({exc.strerror}); set --cache or "
                       "$DATAGEN_CACHE to a writable folder") from None
    if not os.access(root, os.W_OK | os.X_OK):
        raise JobError(f"objects cache {root} is not writable; set --cache or $DATAGEN_CACHE to a writable folder")


def discard_new_job(job: JobDir, remove_dir: bool) -> None:
    """Remove what `JobDir.init` and `prepare_manifest` wrote for a job that never started."""
    from datagen.io.layout import FAILURES_DIR, JOB_JSON, LEDGER_DIR, LOCK, OBJECTS_DIR, SHARDS_DIR

    from datagen.hands.pin import HANDS_DIR

    for f in (job.path / JOB_JSON, job.manifest_failures_path, job.manifest_path, job.manifest_record_path):
        f.unlink(missing_ok=True)
    shutil.rmtree(job.path / HANDS_DIR, ignore_errors=True)  # the hand pin_job_hand kept
    for d in (SHARDS_DIR, FAILURES_DIR, OBJECTS_DIR, LEDGER_DIR):
        try:
            (job.path / d).rmdir()
        except OSError:
            pass
    if remove_dir:
        (job.path / LOCK).unlink(missing_ok=True)
        try:
            job.path.rmdir()
        except OSError:
            pass
