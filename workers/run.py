"""The driver of a dataset job: job directory -> shards -> Ray tasks (`shard.run_shard`) -> ledger.

`run_job` checks the output and the cache and makes the job directory ready (`workers.setup`),
starts or joins the Ray cluster (`workers.cluster`), runs every shard the ledger does not list as
finished (`workers.finished`), with a progress bar, and merges the failures. Crash-consistent: a
shard counts only once its ledger entry is written, so a rerun redoes exactly the others.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
import time
from pathlib import Path

from datagen._interrupt import raise_on_sigterm
from datagen.io.layout import JOB_JSON

from .cluster import connect, error_line, start_local_ray, start_reaper_for, stop_local_ray, worker_slots
from .finished import finished_or_redo, merge_failures, retryable_shards
from .job import AUTO, JobConfig, JobDir, JobError, JobIOError, code_version, package_versions, shard_size, shard_slices
from .setup import check_cache, check_out, discard_new_job, pin_job_hand, prepare_manifest
from .shard import run_shard

__all__ = ["run_job"]

TASK_RETRIES = 3  # a shard whose node dies is rerun elsewhere (shards are idempotent)


def run_job(cfg: JobConfig, out: str | Path, *, address: str | None = None, num_cpus: int | None = None,
            cache: str | None = None, progress: bool = True, retry_failed: bool = False, log=print) -> dict:
    """Run (or resume) the job in directory ``out``; returns `workers.status.job_status`.

    The hand and tasks are checked first (`JobConfig.check_runnable`), so a job that cannot run
    leaves nothing behind. ``retry_failed`` also reruns finished shards whose failures a rerun
    may fix (`retryable_shards`: a timeout, a crash, an unwritable cache, a file restored)."""
    import ray

    from .status import job_status

    if num_cpus is not None and (isinstance(num_cpus, bool) or not isinstance(num_cpus, int) or num_cpus < 1):
        raise JobError(f"--num-cpus must be an integer >= 1 (CPUs of the local Ray cluster), got {num_cpus!r}")
    hand = cfg.check_runnable()
    job = JobDir(out)
    check_out(job.path)
    check_cache(cache)
    existed = job.path.exists()
    try:
        job.lock()
    except OSError as exc:
        raise JobError(f"--out {job.path}: cannot create the job directory: {exc.strerror}") from None
    connected = False
    try:
        for p in job.clean_temp():
            log(f"removed {p.relative_to(job.path)}, left by an interrupted run")
        cfg, connected = _resolve_layout(cfg, job, address, num_cpus)
        resumed = job.init(cfg)
        doc = job.read_job()
        try:
            pin_job_hand(job, hand.spec)
            entries = prepare_manifest(job, cfg)
        except Exception:
            if not resumed:  # leave no half job behind to refuse the corrected command
                discard_new_job(job, remove_dir=not existed)
            raise
        slices = shard_slices(len(entries), cfg.objects_per_shard)
        todo, n_done, n_retried = _shards_to_run(job, len(slices), retry_failed, log)
        log(f"job {job.path}: {len(entries)} objects in {len(slices)} shards; "
            f"{'resuming, ' if resumed else ''}{n_done} done, {len(todo)} to run"
            + (f" ({n_retried} retried for failures)" if retry_failed else ""))
        code = code_version()
        if code != doc["code_version"]:
            log(f"warning: the code changed since this job was created ({doc['code_version']} -> {code}); "
                "shards written now record the new version in their metadata")
        provenance = {"code_version": code, "packages": package_versions(), "hand": hand.name,
                      "created_at": doc["created_at"], "cache": cache or os.environ.get("DATAGEN_CACHE", "")}
        errors: dict[int, str] = {}
        if todo:
            errors = _run_on_ray(ray, job, cfg, entries, slices, todo, provenance, address, num_cpus, progress, log)
        merge_failures(job)
        status = job_status(job.path)
        status["shard_errors"] = errors
        return status
    finally:
        if connected:
            ray.shutdown()
        job.unlock()



def _shards_to_run(job: JobDir, n_shards: int, retry_failed: bool, log) -> tuple[list[int], int, int]:
    """(shards to run, shards done, shards retried): those without a finished ledger; with
    ``retry_failed`` also finished ones whose failures a rerun may fix (their ledgers removed
    first, so readers never see old and new files mixed)."""
    done = finished_or_redo(job, log)
    retry = retryable_shards(job, done) if retry_failed else []
    for i in retry:
        job.ledger_path(i).unlink(missing_ok=True)
        done.pop(i)
    return [i for i in range(n_shards) if i not in done], len(done), len(retry)


def _resolve_layout(cfg: JobConfig, job: JobDir, address: str | None, num_cpus: int | None) -> tuple[JobConfig, bool]:
    """``cfg`` with ``objects_per_shard: auto`` replaced by a number: the one job.json recorded
    when the job was created (a resumed job keeps its shards whatever runs it now), else
    `shard_size` of the object count and the worker slots (`worker_slots`). Returns the config and
    whether this connected to a cluster to count its slots."""
    if cfg.objects_per_shard != AUTO:
        return cfg, False
    if (job.path / JOB_JSON).is_file():
        try:
            stored = job.read_job().get("config", {}).get("objects_per_shard")
        except JobError:  # unreadable: the ledger records it too (`JobDir.init` may then rewrite job.json)
            stored = next((e.get("objects_per_shard") for e in job.audit().finished.values()), None)
        if isinstance(stored, int) and not isinstance(stored, bool) and stored >= 1:
            return dataclasses.replace(cfg, objects_per_shard=stored), False
        # no number recorded (not a job of this code): resolve as for a new job; JobDir.init then
        # names whatever differs
    slots, connected, on_gpus = worker_slots(cfg, address, num_cpus)
    return dataclasses.replace(cfg, objects_per_shard=shard_size(cfg.count, slots, gpu=on_gpus)), connected


def _progress_units(job: JobDir, slices, running) -> float:
    """Objects' worth of work done by the running shards (from their progress files)."""
    total = 0.0
    for i in running:
        try:
            p = json.loads(job.progress_path(i).read_text())
            total += (slices[i][1] - slices[i][0]) * min(1.0, float(p["done"]) / max(float(p["total"]), 1e-9))
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return total


def _run_on_ray(ray, job, cfg, entries, slices, todo, provenance, address, num_cpus, progress, log) -> dict:
    address = address or os.environ.get("RAY_ADDRESS") or None
    private_tmp = None
    started = False
    for i in todo:  # a killed run's progress is stale
        job.progress_path(i).unlink(missing_ok=True)
    reaper = None
    if not ray.is_initialized():
        if address and address != "local":  # "local": Ray's name for a new local cluster
            connect(ray, address)
        else:
            private_tmp = start_local_ray(ray, job, num_cpus, log)
            reaper = start_reaper_for(ray)
        started = True
    raise_on_sigterm()  # again: Ray's core worker replaced the handler with one that dumps native stacks
    try:
        gpus = cfg.gpus_per_shard if ray.cluster_resources().get("GPU", 0) > 0 else 0
        task = ray.remote(run_shard).options(num_cpus=cfg.cpus_per_shard, num_gpus=gpus, max_retries=TASK_RETRIES,
                                             retry_exceptions=False)
        cfg_d = cfg.to_dict()
        refs = {task.remote(str(job.path), i, _shard_entries(entries, slices[i]), cfg_d, provenance): i for i in todo}
        t0 = time.perf_counter()
        errors = _collect(ray, job, refs, entries, slices, todo, progress, log)
        log(f"ran {len(todo)} shards in {time.perf_counter() - t0:.1f} s")
        return errors
    finally:
        if started:
            stop_local_ray(ray)  # a driver connected to a cluster owns no Ray process: plain ray.shutdown()
        if reaper is not None:
            reaper.close()
        if private_tmp:
            shutil.rmtree(private_tmp, ignore_errors=True)


def _shard_entries(entries: list, span: tuple[int, int]) -> list[dict]:
    """The manifest entries ``entries[a:b]`` of one shard as plain dicts (what a Ray task takes)."""
    a, b = span
    return [{**e.__dict__, "scales": list(e.scales)} for e in entries[a:b]]


def _collect(ray, job: JobDir, refs: dict, entries: list, slices, todo: list[int], progress: bool, log) -> dict:
    """Waits for the shard tasks ``refs`` (ref -> shard index), updating the progress bar; returns
    {shard: error line} of the shards that failed (a rerun redoes them). A full disk in any shard
    cancels the others and raises its `JobIOError`."""
    bar = None
    finished_objects = float(len(entries) - sum(slices[i][1] - slices[i][0] for i in todo))
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(entries), initial=finished_objects, desc="objects", unit="obj", file=sys.stderr,
                   smoothing=0.05, bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total} "
                                              "[{elapsed}<{remaining}{postfix}]")
    grasps = ok = 0
    errors: dict[int, str] = {}
    pending = list(refs)
    while pending:
        ready, pending = ray.wait(pending, num_returns=1, timeout=1.0)
        for ref in ready:
            i = refs[ref]
            try:
                s = ray.get(ref)
                grasps, ok = grasps + s["grasps"], ok + s["success"]
            except Exception as exc:  # noqa: BLE001 - the shard stays unfinished; a rerun redoes it
                cause = getattr(exc, "cause", None)
                if isinstance(cause, JobIOError):  # a full disk: every other shard would fail the same way
                    for r in pending:
                        ray.cancel(r, force=True)
                    if bar is not None:
                        bar.close()
                    raise cause from None
                errors[i] = error_line(exc)
                log(f"shard {i} failed: {errors[i]} (rerun the command to retry it)")
            finished_objects += slices[i][1] - slices[i][0]
        if bar is not None:
            running = [refs[r] for r in pending]
            bar.update(finished_objects + _progress_units(job, slices, running) - bar.n)
            bar.set_postfix(shards=f"{len(refs) - len(pending)}/{len(refs)}", grasps=grasps,
                            success=f"{ok / max(grasps, 1):.0%}", refresh=False)
    if bar is not None:
        bar.close()
    return errors


