"""The Ray driver of a dataset job: manifest -> shards -> Ray tasks (`shard.run_shard`) -> ledger.

Without an address (argument or ``RAY_ADDRESS``) it starts a local Ray with every core, no
dashboard, and its temp dir inside the job directory. Ray puts Unix sockets under
``<temp>/session_<date>_<pid>/sockets/``, and a socket path may not exceed 107 bytes, so when
``<job>/ray`` is longer than `MAX_RAY_TEMP_LEN` characters a short ``/tmp/dg-ray-XXXX`` is used
instead (named by a hash of the job path; printed, and removed at the end). With an address it joins that cluster; the
job directory and the objects cache must then be on a file system every node sees, and every
node needs this package installed.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from schemas import arrow_schema

from .job import JobConfig, JobDir, JobError, code_version, package_versions, shard_slices
from .shard import run_shard, write_table_atomic

__all__ = ["run_job", "prepare_manifest", "merge_failures", "MAX_RAY_TEMP_LEN"]

MAX_RAY_TEMP_LEN = 40
TASK_RETRIES = 3  # a shard whose node dies is rerun elsewhere (shards are idempotent)


def prepare_manifest(job: JobDir, cfg: JobConfig) -> list:
    """The job's manifest slice: read back when present (resume), else built or cut from
    ``cfg.manifest`` and written atomically."""
    from datagen.objects.manifest import build_manifest, load_manifest, write_manifest

    if job.manifest_path.is_file():
        return load_manifest(job.manifest_path)
    if cfg.manifest:
        entries = load_manifest(cfg.manifest)[: cfg.count]
        if len(entries) < cfg.count:
            print(f"warning: manifest {cfg.manifest} has {len(entries)} objects, fewer than count {cfg.count}",
                  file=sys.stderr)
    else:
        entries = build_manifest(cfg.source, cfg.count, cfg.scales, cfg.test_fraction)
    if not entries:
        raise JobError(f"job {job.path}: the manifest is empty (source {cfg.source!r}, manifest {cfg.manifest!r})")
    write_manifest(entries, job.manifest_path)
    return entries


def merge_failures(job: JobDir) -> pa.Table:
    """Concatenate the shards' failure files into ``failures.parquet`` (atomically)."""
    schema = arrow_schema("failures")
    parts = [pq.read_table(p) for p in sorted((job.path / "failures").glob("part-*.parquet"))]
    table = pa.concat_tables([p.cast(schema) for p in parts]) if parts else schema.empty_table()
    write_table_atomic(table, job.failures_path)
    return table


def _ray_temp_dir(job: JobDir) -> tuple[str, bool]:
    """(temp dir, is_private_tmp)."""
    inside = job.path / "ray"
    if len(str(inside)) <= MAX_RAY_TEMP_LEN:
        inside.mkdir(parents=True, exist_ok=True)
        return str(inside), False
    # a name fixed by the job path: a resumed run reuses (and finally removes) a killed run's dir
    short = Path("/tmp") / f"dg-ray-{hashlib.sha256(str(job.path).encode()).hexdigest()[:10]}"
    short.mkdir(exist_ok=True)
    return str(short), True


def run_job(cfg: JobConfig, out: str | Path, *, address: str | None = None, num_cpus: int | None = None,
            cache: str | None = None, progress: bool = True, log=print) -> dict:
    """Run (or resume) the job in directory ``out``; returns `workers.status.job_status`."""
    import ray

    from .status import job_status

    job = JobDir(out)
    job.lock()
    try:
        resumed = job.init(cfg)
        doc = job.read_job()
        entries = prepare_manifest(job, cfg)
        slices = shard_slices(len(entries), cfg.objects_per_shard)
        done = job.finished()
        todo = [i for i in range(len(slices)) if i not in done]
        log(f"job {job.path}: {len(entries)} objects in {len(slices)} shards; "
            f"{'resuming, ' if resumed else ''}{len(done)} done, {len(todo)} to run")
        code = code_version()
        if code != doc["code_version"]:
            log(f"warning: the code changed since this job was created ({doc['code_version']} -> {code}); "
                "shards written now record the new version in their metadata")
        provenance = {"code_version": code, "packages": package_versions(),
                      "created_at": doc["created_at"], "cache": cache or os.environ.get("DATAGEN_CACHE", "")}
        errors: dict[int, str] = {}
        if todo:
            errors = _run_on_ray(ray, job, cfg, entries, slices, todo, provenance, address, num_cpus, progress, log)
        merge_failures(job)
        status = job_status(job.path)
        status["shard_errors"] = errors
        return status
    finally:
        job.unlock()


def _run_on_ray(ray, job, cfg, entries, slices, todo, provenance, address, num_cpus, progress, log) -> dict:
    address = address or os.environ.get("RAY_ADDRESS") or None
    private_tmp = None
    started = False
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            tmp, private = _ray_temp_dir(job)
            private_tmp = tmp if private else None
            if private:
                log(f"ray temp dir {tmp} (the job path is too long for Ray's Unix sockets)")
            ray.init(num_cpus=num_cpus or os.cpu_count(), include_dashboard=False, _temp_dir=tmp,
                     log_to_driver=False, configure_logging=False)
        started = True
    try:
        gpus = cfg.gpus_per_shard if ray.cluster_resources().get("GPU", 0) > 0 else 0
        task = ray.remote(run_shard).options(num_cpus=cfg.cpus_per_shard, num_gpus=gpus, max_retries=TASK_RETRIES,
                                             retry_exceptions=False)
        cfg_d = cfg.to_dict()
        refs = {}
        for i in todo:
            a, b = slices[i]
            shard_entries = [{**e.__dict__, "scales": list(e.scales)} for e in entries[a:b]]
            refs[task.remote(str(job.path), i, shard_entries, cfg_d, provenance)] = i
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(slices), initial=len(slices) - len(todo), desc="shards", unit="shard",
                       file=sys.stderr)
        grasps = ok = 0
        errors: dict[int, str] = {}
        pending = list(refs)
        t0 = time.perf_counter()
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            i = refs[ready[0]]
            try:
                s = ray.get(ready[0])
                grasps, ok = grasps + s["grasps"], ok + s["success"]
            except Exception as exc:  # noqa: BLE001 - the shard stays unfinished; a rerun redoes it
                errors[i] = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                log(f"shard {i} failed: {errors[i]} (rerun the command to retry it)")
            if bar is not None:
                bar.update(1)
                bar.set_postfix(grasps=grasps, success=f"{ok / max(grasps, 1):.0%}")
        if bar is not None:
            bar.close()
        log(f"ran {len(todo)} shards in {time.perf_counter() - t0:.1f} s")
        return errors
    finally:
        if started:
            ray.shutdown()
        if private_tmp:
            shutil.rmtree(private_tmp, ignore_errors=True)
