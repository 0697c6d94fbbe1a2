"""The Ray driver of a dataset job: manifest -> shards -> Ray tasks (`shard.run_shard`) -> ledger.

Without an address (argument or ``RAY_ADDRESS``) it starts a local Ray with every core, no
dashboard, every port on the loopback interface and its temp dir inside the job directory
(`start_local_ray`). Ray puts Unix sockets under
``<temp>/session_<date>_<pid>/sockets/``, and a socket path may not exceed 107 bytes, so when
``<job>/ray`` is longer than `MAX_RAY_TEMP_LEN` characters a short ``/tmp/dg-ray-XXXX`` is used
instead (named by a hash of the job path; printed, and removed at the end). With an address it joins that cluster; the
job directory and the objects cache must then be on a file system every node sees, and every
node needs this package installed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import re
import shutil
import sys
import time
from pathlib import Path

import pyarrow as pa

from schemas import arrow_schema

from datagen._interrupt import raise_on_sigterm
from datagen.io import integrity
from datagen.io.layout import JOB_JSON

from .job import (AUTO, JobConfig, JobDir, JobError, JobIOError, code_version, package_versions, shard_size,
                  shard_slices, writing)
from .shard import _failure, run_shard, write_table_atomic

__all__ = ["run_job", "prepare_manifest", "pin_job_hand", "merge_failures", "retryable_shards", "error_line", "FINAL_REASONS",
           "MAX_RAY_TEMP_LEN", "start_local_ray", "stop_local_ray", "worker_slots"]

MAX_RAY_TEMP_LEN = 40
LOOPBACK = "127.0.0.1"  # the local cluster's node address: Ray then listens on loopback only
TASK_RETRIES = 3  # a shard whose node dies is rerun elsewhere (shards are idempotent)


# failure reasons decided by an object's bytes: cached with the object, so a retry cannot change
# them; every other failure (timeout, crashed, error, missing_file, ...) is retried by
# `run_job(retry_failed=True)`
FINAL_REASONS = frozenset({"unreadable_mesh", "empty_mesh", "non_finite_vertices", "huge_coordinates", "too_many_faces",
                           "degenerate_mesh", "coacd_failed", "coacd_no_parts", "surface_failed", "mjcf_failed"})


def prepare_manifest(job: JobDir, cfg: JobConfig) -> list:
    """The job's manifest slice: read back when present (resume), else built or cut from
    ``cfg.manifest`` and written atomically. Objects of the source that cannot be manifest
    entries become rows of ``failures/manifest.parquet`` (stage ``manifest``)."""
    from datagen.objects.errors import ManifestError
    from datagen.objects.manifest import build_manifest, load_manifest, write_manifest

    if job.manifest_path.is_file():
        try:
            return load_manifest(job.manifest_path, check_paths=False)
        except ManifestError as exc:
            raise JobError(f"job {job.path}: its manifest no longer loads ({exc}); start the job in a new "
                           "--out") from None
    rejected = []
    if cfg.manifest:
        entries = load_manifest(cfg.manifest)[: cfg.count]
        if len(entries) < cfg.count:
            print(f"warning: manifest {cfg.manifest} has {len(entries)} objects, fewer than count {cfg.count}",
                  file=sys.stderr)
    else:
        entries = build_manifest(cfg.source, cfg.count, cfg.scales, cfg.test_fraction, rejected=rejected,
                                 max_mesh_bytes=cfg.recipes()[0].process.max_mesh_bytes)
    rows: list[dict] = []
    for r in rejected:  # shard -1: before any shard
        _failure(rows, -1, r.id, "manifest", r.reason, r.message)
    write_table_atomic(pa.Table.from_pylist(rows, schema=arrow_schema("failures")), job.manifest_failures_path)
    if not entries:
        raise JobError(f"job {job.path}: the manifest is empty (source {cfg.source!r}, manifest {cfg.manifest!r})"
                       + "".join(f"\n  {r.message}" for r in rejected[:5]))
    with writing(job.manifest_path, "the job's manifest"):
        write_manifest(entries, job.manifest_path)
    return entries


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


def error_line(exc: BaseException) -> str:
    """One line naming an exception from a Ray task: its cause, without traceback or colours."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        exc = cause
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return f"{type(exc).__name__}: {lines[-1] if lines else ''}"


def _ray_temp_dir(job: JobDir) -> tuple[str, bool]:
    """(temp dir, is_private_tmp)."""
    inside = job.path / "ray"
    if len(str(inside)) <= MAX_RAY_TEMP_LEN:
        inside.mkdir(mode=0o700, parents=True, exist_ok=True)
        os.chmod(inside, 0o700)
        return str(inside), False
    # a name fixed by the job path: a resumed run reuses (and finally removes) a killed run's dir
    short = Path("/tmp") / f"dg-ray-{hashlib.sha256(str(job.path).encode()).hexdigest()[:10]}"
    short.mkdir(mode=0o700, exist_ok=True)
    if short.owner() != __import__("getpass").getuser():
        raise JobError(f"{short} (Ray's temp dir for this job) belongs to another user; remove it")
    os.chmod(short, 0o700)
    return str(short), True


class _DropNotice(logging.Filter):
    def __init__(self, prefix: str) -> None:
        super().__init__()
        self.prefix = prefix

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(self.prefix)


def start_local_ray(ray, job: JobDir, num_cpus: int | None, log=print) -> str | None:
    """Start the job's local Ray: every core (or ``num_cpus``), no dashboard, its temp dir private
    (`_ray_temp_dir`), every port on the loopback interface. Returns the temp dir to remove at the
    end (a ``/tmp/dg-ray-*`` one), else None.

    Ray binds its gRPC servers (GCS, raylet, object manager, each worker's), its agents and the
    metrics exporter to the loopback interface when the node's address is loopback, but on Linux
    it replaces a loopback ``_node_ip_address`` by the machine's address unless its single-machine
    mode is on (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, the default on macOS and Windows; read
    when ``ray`` is imported, so it is set here on Ray's constant for the duration of ``init``).
    """
    tmp, private = _ray_temp_dir(job)
    if private:
        log(f"ray temp dir {tmp} (the job path is too long for Ray's Unix sockets)")
    constants = getattr(getattr(ray, "_private", None), "ray_constants", None)
    single = getattr(constants, "ENABLE_RAY_CLUSTER", None)
    if single is not None:
        constants.ENABLE_RAY_CLUSTER = False
    notice = logging.getLogger("ray._private.authentication.authentication_token_setup")
    quiet = _DropNotice("Token authentication is enabled")  # the default, said at every start; a warning
    notice.addFilter(quiet)                                   # that it is disabled still shows
    try:
        ray.init(num_cpus=num_cpus or os.cpu_count(), include_dashboard=False, _temp_dir=tmp,
                 _node_ip_address=LOOPBACK, log_to_driver=False, configure_logging=False)
    finally:
        notice.removeFilter(quiet)
        if single is not None:
            constants.ENABLE_RAY_CLUSTER = single
    os.chmod(tmp, 0o700)  # Ray makes it world-writable; its sockets and logs are ours only
    node_ip = ray.util.get_node_ip_address()
    if node_ip not in (LOOPBACK, "::1"):
        log(f"warning: Ray {ray.__version__} put the local cluster on {node_ip}, not on the loopback interface: "
            "its ports listen on every interface; on a shared network, firewall them")
    return tmp if private else None


def stop_local_ray(ray) -> None:
    """``ray.shutdown()`` of a local cluster this process started, 1 s sooner.

    Ray's shutdown stops its processes one after another, each with SIGTERM and up to 1 s to
    exit. The autoscaler monitor ignores SIGTERM, so every job waited the full second for it (Ray
    2.60: 1.37 -> 0.33 s per shutdown on the project's machine). A local cluster has one node and
    never scales: the monitor is killed first, then Ray stops the rest as usual. The monitor is
    looked up through Ray's private node object; where there is none (a driver connected to a
    cluster owns no Ray process, or another Ray version), this is plain ``ray.shutdown()``."""
    node = getattr(getattr(getattr(ray, "_private", None), "worker", None), "_global_node", None)
    for info in (getattr(node, "all_processes", None) or {}).get("monitor", []):
        proc = getattr(info, "process", None)
        try:
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait(timeout=5)
        except Exception:  # noqa: BLE001 - ray.shutdown below stops it the slow way
            pass
    ray.shutdown()


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
    _check_out(job.path)
    _check_cache(cache)
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
                _discard_new_job(job, remove_dir=not existed)
            raise
        slices = shard_slices(len(entries), cfg.objects_per_shard)
        done = _finished_or_redo(job, log)
        retry = retryable_shards(job, done) if retry_failed else []
        for i in retry:  # unfinished until rerun: readers never see old and new files mixed
            job.ledger_path(i).unlink(missing_ok=True)
            done.pop(i)
        todo = [i for i in range(len(slices)) if i not in done]
        log(f"job {job.path}: {len(entries)} objects in {len(slices)} shards; "
            f"{'resuming, ' if resumed else ''}{len(done)} done, {len(todo)} to run"
            + (f" ({len(retry)} retried for failures)" if retry_failed else ""))
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


def _finished_or_redo(job: JobDir, log) -> dict[int, dict]:
    """The finished shards whose files match their ledger entry to the sha256 (`JobDir.audit`,
    deep); a shard whose file is missing, truncated or changed, or whose entry cannot be read,
    loses its entry (said, with why) and is redone: its seed is fixed, so are its rows."""
    found = job.audit(deep=True)
    for i, why in sorted(found.problems.items()):
        log(f"shard {i}: {why}; redoing it")
        job.ledger_path(i).unlink(missing_ok=True)
    return found.finished


def worker_slots(cfg: JobConfig, address: str | None, num_cpus: int | None) -> tuple[int, bool, bool]:
    """(shard tasks that can run at once, whether this connected to a Ray cluster to count them,
    whether the shards get GPUs).

    Local: ``num_cpus`` (or every core) over ``cpus_per_shard``, and this machine's CUDA devices
    over ``gpus_per_shard`` when it has any. A cluster (``address`` or $RAY_ADDRESS, not "local"):
    its CPUs over ``cpus_per_shard``, and its GPUs over ``gpus_per_shard`` when it has GPUs, as Ray
    reports them now. The scarcer resource sets the count: a shard task asks for both."""
    import ray

    address = address or os.environ.get("RAY_ADDRESS") or None
    connected = False
    if address and address != "local":
        if not ray.is_initialized():
            _connect(ray, address)
            connected = True
            raise_on_sigterm()
        res = ray.cluster_resources()
        cpus, gpus = res.get("CPU", 1.0), res.get("GPU", 0)
    else:
        import torch

        cpus, gpus = num_cpus or os.cpu_count() or 1, torch.cuda.device_count() if torch.cuda.is_available() else 0
    slots = cpus / cfg.cpus_per_shard
    on_gpus = gpus > 0 and cfg.gpus_per_shard > 0
    if on_gpus:
        slots = min(slots, gpus / cfg.gpus_per_shard)
    return max(1, int(slots + 1e-9)), connected, on_gpus


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


def _discard_new_job(job: JobDir, remove_dir: bool) -> None:
    """Remove what `JobDir.init` and `prepare_manifest` wrote for a job that never started."""
    from datagen.io.layout import FAILURES_DIR, JOB_JSON, LEDGER_DIR, LOCK, OBJECTS_DIR, SHARDS_DIR

    from datagen.hands.pin import HANDS_DIR

    for f in (job.path / JOB_JSON, job.manifest_failures_path, job.manifest_path):
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


def _check_out(path: Path) -> None:
    """A usable job directory: not a file, and writable (JobError naming the problem)."""
    if path.exists() and not path.is_dir():
        raise JobError(f"--out {path} is an existing file, not a job directory; choose another --out")
    probe = path
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise JobError(f"--out {path}: cannot write in {probe} (permission denied); choose another --out")


def _check_cache(cache: str | None) -> None:
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
            _connect(ray, address)
        else:
            private_tmp = start_local_ray(ray, job, num_cpus, log)
            reaper = _start_reaper(ray)
        started = True
    raise_on_sigterm()  # again: Ray's core worker replaced the handler with one that dumps native stacks
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
        finished_objects = float(len(entries) - sum(slices[i][1] - slices[i][0] for i in todo))
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(entries), initial=finished_objects, desc="objects", unit="obj", file=sys.stderr,
                       smoothing=0.05, bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total} "
                                                  "[{elapsed}<{remaining}{postfix}]")
        grasps = ok = 0
        errors: dict[int, str] = {}
        pending = list(refs)
        t0 = time.perf_counter()
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
        log(f"ran {len(todo)} shards in {time.perf_counter() - t0:.1f} s")
        return errors
    finally:
        if started:
            stop_local_ray(ray)  # a driver connected to a cluster owns no Ray process: plain ray.shutdown()
        if reaper is not None:
            reaper.close()
        if private_tmp:
            shutil.rmtree(private_tmp, ignore_errors=True)


def _start_reaper(ray):
    """The reaper of the local cluster just started (`workers.reaper`: it dies with this driver,
    even a SIGKILLed one), or None where Ray does not say its session directory."""
    from .reaper import start_reaper

    node = getattr(getattr(getattr(ray, "_private", None), "worker", None), "_global_node", None)
    try:
        return start_reaper(node.get_session_dir_path())
    except Exception:  # noqa: BLE001 - another Ray version: only ray.shutdown stops the cluster
        return None


def _connect(ray, address: str) -> None:
    """Join the Ray cluster at ``address`` (`JobError` naming it when none answers)."""
    try:
        ray.init(address=address, log_to_driver=False)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise JobError(f"--address {address}: cannot connect to a Ray cluster there ({error_line(exc)})",
                       "start it with `ray start --head`, or pass the address `ray status` names") from None
