"""The per-shard pipeline as a plain function: objects (cached, isolated) -> synthesis -> MuJoCo
evaluation -> one Parquet shard. Ray calls `run_shard`; tests call it directly.

Every object is processed in its own process with a time limit, so a crashing or hanging CoACD
costs that object, not the shard. Anything that fails for an object (processing, its synthesis
target, the batch's synthesis or evaluation) becomes a `failures` row with a stage and reason.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing as mp
import os
import pickle
import shutil
import socket
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from schemas import arrow_schema

from .job import JobConfig, JobDir

__all__ = ["run_shard", "process_isolated", "write_table_atomic", "shard_seed"]

_HANDS: dict = {}  # hand name -> HandModel, reused by a Ray worker across shards


def shard_seed(cfg: JobConfig, index: int) -> int:
    """Synthesis seed of shard ``index`` (recorded in every row)."""
    return int(cfg.seed) + int(index)


def _process_child(conn, source, path, object_id, family, pcfg_dict, cache, sha) -> None:
    """Process one object; always sends (status, reason, message, entry) unless the process dies."""
    try:
        from datagen.objects.config import ProcessConfig
        from datagen.objects.errors import ObjectError
        from datagen.objects.process import process_object
        from datagen.objects.sources import resolve

        try:
            ref = resolve(source, path, object_id, family)
            p = process_object(ref, ProcessConfig.from_dict(pcfg_dict), root=cache, expected_sha256=sha)
            msg = (p.status, p.reason, p.message, str(p.entry) if p.entry else "")
        except ObjectError as exc:
            msg = ("failed", exc.reason.value, str(exc), "")
    except Exception as exc:  # noqa: BLE001 - e.g. an unwritable cache: a cause, not a crash
        msg = ("failed", "error", f"{object_id}: {type(exc).__name__}: {exc}", "")
    conn.send(msg)
    conn.close()


def process_isolated(entry, pcfg, cache: str | None, timeout_s: float):
    """``(ProcessedObject or None, reason, message)`` of a manifest entry.

    The file is read and hashed here first: a missing file (``missing_file``), one that is not
    a regular file inside the source root, or one whose bytes are not the manifest's sha256
    (``sha256_mismatch``) is a failure, never a cache hit under the manifest's hash. Then the
    cache entry of those bytes (`datagen.objects.process.cached`, labelled with this entry's id)
    if present, else a fresh process killed after ``timeout_s`` (reason ``timeout``) or if it
    dies (``crashed``)."""
    import hashlib

    from datagen.objects.cache import cache_root
    from datagen.objects.errors import ObjectError, Reason
    from datagen.objects.process import as_object, cached, load_processed

    try:
        ref = entry.ref()
        sha = hashlib.sha256(ref.read_bytes()).hexdigest()
        if sha != entry.sha256:
            return None, Reason.SHA_MISMATCH.value, (f"{entry.id}: {Reason.SHA_MISMATCH.value}: file sha256 "
                                                     f"{sha[:12]}... != manifest {entry.sha256[:12]}...; the file "
                                                     "changed since the manifest was built: rebuild it")
        hit = cached(ref, sha, pcfg, cache)
    except ObjectError as exc:
        return None, exc.reason.value, str(exc)
    except OSError as exc:
        return None, "error", f"{entry.id}: {type(exc).__name__}: {exc}"
    if hit is not None:
        return (hit, "", "") if hit.ok else (None, hit.reason, hit.message)
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_process_child, args=(child, entry.source, entry.path, entry.id, entry.family,
                                                    pcfg.to_dict(), str(cache_root(cache)), entry.sha256),
                       daemon=True)
    proc.start()
    child.close()
    try:
        if not parent.poll(timeout_s):
            return None, "timeout", (f"{entry.id}: processing exceeded {timeout_s:g} s and was killed (raise "
                                     "object_timeout_s and rerun with --retry-failed)")
        try:
            status, reason, message, path = parent.recv()
        except EOFError:
            proc.join(5)
            return None, "crashed", f"{entry.id}: the processing process died (exit code {proc.exitcode})"
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join(5)
        parent.close()
    if status != "ok":
        return None, reason, message
    return as_object(load_processed(Path(path)), ref), "", ""


def _link_into_job(processed, job: JobDir) -> str:
    """Hard-link (or copy) a processed-object directory into the job; returns its path
    relative to the job directory."""
    rel = Path("objects") / processed.entry.name
    dst = job.path / rel
    if not (dst / "meta.json").is_file():
        tmp = dst.with_name(f".{dst.name}.{os.getpid()}.tmp")
        shutil.rmtree(tmp, ignore_errors=True)

        def link(src, d):
            try:
                os.link(src, d)
            except OSError:
                shutil.copy2(src, d)

        shutil.copytree(processed.entry, tmp, copy_function=link)
        try:
            os.replace(tmp, dst)
        except OSError:  # another attempt won the race
            shutil.rmtree(tmp, ignore_errors=True)
    return str(rel)


def write_table_atomic(table: pa.Table, path: Path) -> None:
    """Write Parquet to a temp name in the same directory and rename: the final name holds
    either nothing or a complete file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{time.monotonic_ns()}.tmp")
    try:
        pq.write_table(table, tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _failure(fails: list, shard: int, object_id: str, stage: str, reason: str, message: str,
             scale: float = float("nan"), task: str = "") -> None:
    fails.append({"object_id": object_id, "object_scale_m": scale, "task": task, "stage": stage,
                  "reason": reason or "error", "message": message, "shard": shard})


def _hand(name: str, device: str):
    from datagen.hands import load_hand

    key = (name, device)
    if key not in _HANDS:
        _HANDS[key] = load_hand(name, device=device)
    return _HANDS[key]


def task_targets(task, targets: list) -> list:
    """The targets a task runs on: a task whose YAML names its object (``eval.object``, the
    task-benchmark tasks) only that object (``task-<name>`` of the ``tasks`` source), other
    tasks every target."""
    from datagen.tasks import task_object
    from datagen.objects.task_objects import object_id

    name = task_object(task)
    return list(targets) if name is None else [t for t in targets if t.object_id == object_id(name)]


def run_shard(job_path: str, index: int, entries: list[dict], cfg_dict: dict, provenance: dict) -> dict:
    """Run shard ``index`` over manifest ``entries`` (dicts of ManifestEntry fields) and write
    its shard, failures and ledger entry. Returns the ledger summary. Idempotent: a rerun
    overwrites the same files with the same rows. An exception that cannot be pickled (Ray
    would report it as ``UnserializableException``, losing its cause) is raised as a
    RuntimeError carrying its type and message."""
    cache, before = provenance.get("cache") or None, os.environ.get("DATAGEN_CACHE")
    if cache:  # the hand cache (flattened MJCFs) follows the objects cache, for this shard only
        os.environ["DATAGEN_CACHE"] = cache
    try:
        return _run_shard(job_path, index, entries, cfg_dict, provenance)
    except Exception as exc:
        try:
            pickle.loads(pickle.dumps(exc))
        except Exception:  # noqa: BLE001
            raise RuntimeError(f"shard {index}: {type(exc).__name__}: {exc}") from None
        raise
    finally:
        if before is None:
            os.environ.pop("DATAGEN_CACHE", None)
        else:
            os.environ["DATAGEN_CACHE"] = before


def _run_shard(job_path: str, index: int, entries: list[dict], cfg_dict: dict, provenance: dict) -> dict:
    import torch

    from datagen.objects.manifest import ManifestEntry
    from datagen.objects.process import load_processed
    from datagen.synth import GraspTarget, synthesize
    from datagen.tasks import load_task
    from datagen.synth.rows import result_table
    from datagen.eval.table import evaluate_table

    t_start, cpu_start = time.perf_counter(), time.process_time()
    job = JobDir(job_path)
    cfg = JobConfig.from_dict(cfg_dict)
    pcfg, scfg, ecfg = cfg.build_configs()
    torch.set_num_threads(max(1, int(cfg.cpus_per_shard)))
    device = "cuda" if torch.cuda.is_available() else "cpu"
    cache = provenance.get("cache") or None
    n_targets = sum(len(d["scales"]) for d in entries)
    progress = ShardProgress(job.progress_path(index), total=2 * len(entries) + 2 * len(cfg.tasks) * n_targets)
    timings = {"process_s": 0.0, "target_s": 0.0, "synth_s": 0.0, "eval_s": 0.0, "write_s": 0.0}
    fails: list[dict] = []
    tables: list[pa.Table] = []

    # 1. objects
    t0 = time.perf_counter()
    ready = []  # (ManifestEntry, processed object inside the job dir, relative path)
    for d in entries:
        e = ManifestEntry(**{**d, "scales": tuple(d["scales"])})
        try:
            p, reason, message = process_isolated(e, pcfg, cache, cfg.object_timeout_s)
            if p is None:
                _failure(fails, index, e.id, "process", reason, message)
                continue
            rel = _link_into_job(p, job)
            ready.append((e, load_processed(job.path / rel), rel))
        except Exception as exc:  # noqa: BLE001 - recorded, never fatal
            _failure(fails, index, e.id, "process", "error", f"{e.id}: {type(exc).__name__}: {exc}")
        finally:
            progress.add(1)
    timings["process_s"] = time.perf_counter() - t0

    # 2. synthesis targets
    t0 = time.perf_counter()
    targets = []
    for e, p, rel in ready:
        try:
            # the SDF and its grid are in normalized units: build them once, rescale the hull samples
            base = GraspTarget.from_processed(p, e.scales[0], grid_resolution=cfg.grid_resolution, cache=cache)
        except Exception as exc:  # noqa: BLE001
            _failure(fails, index, e.id, "target", "error", f"{e.id}: {type(exc).__name__}: {exc}")
            continue
        finally:
            progress.add(1)
        for s in e.scales:  # the manifest's scales (a built manifest has the config's)
            # the id is the manifest's: the processed object may be a cache entry made for
            # another object with the same bytes (its meta names that one)
            t = dataclasses.replace(base, object_id=e.id, scale=float(s),
                                    hull_points=base.hull_points * (s / base.scale), object_path=rel,
                                    mesh_sha256=e.sha256)
            targets.append(t.to(device) if device != "cpu" else t)
    timings["target_s"] = time.perf_counter() - t0
    progress.set(2 * len(entries))

    hand = _hand(cfg.hand, device) if targets else None
    all_targets = targets
    for k, task_name in enumerate(cfg.tasks):
        progress.set(2 * len(entries) + 2 * k * n_targets)
        task = load_task(task_name)
        targets = task_targets(task, all_targets)
        if not targets:
            continue
        # 3. synthesis, one batch for the shard
        t0 = time.perf_counter()
        try:
            scfg_k = dataclasses.replace(scfg, seed=shard_seed(cfg, index))
            base_units = progress.done

            def moved(it, *_):  # progress per optimizer iteration (reads nothing of the state)
                progress.set(base_units + n_targets * (it + 1) / max(scfg_k.iters, 1))

            result = synthesize(hand, targets, task, scfg_k, cfg.grasps_per_object, callback=moved)
            table = result_table(result, targets, hand, task, scfg_k, splits={e.id: e.split for e, _, _ in ready})
        except Exception as exc:  # noqa: BLE001
            for t in targets:
                _failure(fails, index, t.object_id, "synth", "error", f"{t.object_id} at {t.scale} m, task "
                         f"{task.name}: {type(exc).__name__}: {exc}", t.scale, task.name)
            timings["synth_s"] += time.perf_counter() - t0
            continue
        timings["synth_s"] += time.perf_counter() - t0
        progress.set(base_units + n_targets)
        # 4. MuJoCo evaluation, per object so one bad object costs only its rows
        t0 = time.perf_counter()
        for t in targets:
            progress.add(n_targets / len(targets))
            mask = pc.and_(pc.equal(table["object_id"], t.object_id),
                                   pc.equal(table["object_scale_m"], pa.scalar(t.scale, pa.float32())))
            part = table.filter(mask)
            try:
                tables.append(evaluate_table(part, ecfg, base=job.path, workers=1))
            except Exception as exc:  # noqa: BLE001
                _failure(fails, index, t.object_id, "eval", "error", f"{t.object_id} at {t.scale} m, task "
                         f"{task.name}: {type(exc).__name__}: {exc}", t.scale, task.name)
        timings["eval_s"] += time.perf_counter() - t0

    # 5. write: shard (if it has rows), failures, then the ledger entry
    t0 = time.perf_counter()
    nq = 7 + (hand.num_joints if hand is not None else _hand(cfg.hand, "cpu").num_joints)
    joint_names = (hand or _hand(cfg.hand, "cpu")).joint_names
    schema = arrow_schema("evaluated", nq=nq)
    meta = dict(schema.metadata)
    meta.update({k.encode(): (v if isinstance(v, str) else json.dumps(v, sort_keys=True)).encode() for k, v in {
        "datagen.joint_names": joint_names, "datagen.code_version": provenance["code_version"],
        "datagen.config_hash": cfg.hash(), "datagen.packages": provenance["packages"],
        "datagen.host": socket.gethostname(), "datagen.job_created_at": provenance["created_at"],
        "datagen.written_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "datagen.shard": str(index), "datagen.seed": str(shard_seed(cfg, index)),
        "datagen.synth_config": dataclasses.replace(scfg, seed=shard_seed(cfg, index)).to_dict(),
        "datagen.eval_config": ecfg.to_dict(),
        "datagen.process_config": pcfg.to_dict()}.items()})
    schema = schema.with_metadata(meta)
    if tables:
        out = pa.concat_tables([tb.select(schema.names).cast(schema.remove_metadata()) for tb in tables])
        out = out.replace_schema_metadata(meta)
        write_table_atomic(out, job.shard_path(index))
    else:  # no rows: no shard file (some readers, e.g. Hugging Face datasets, reject empty Parquet files)
        out = schema.empty_table()
        job.shard_path(index).unlink(missing_ok=True)
    write_table_atomic(pa.Table.from_pylist(fails, schema=arrow_schema("failures")), job.shard_failures_path(index))
    timings["write_s"] = time.perf_counter() - t0
    n_ok = int(pc.sum(out["success"]).as_py() or 0) if out.num_rows else 0
    summary = {"shard": index, "objects": len(entries), "objects_ok": len(ready), "grasps": out.num_rows,
               "success": n_ok, "failures": len(fails), "host": socket.gethostname(), "device": device,
               "timings": {k: round(v, 3) for k, v in timings.items()},
               "wall_s": round(time.perf_counter() - t_start, 3),
               "cpu_s": round(time.process_time() - cpu_start, 3)}  # this process (not the CoACD children)
    job.record_finished(index, summary)
    progress.set(progress.total)
    return summary


class ShardProgress:
    """A running shard's progress, ``{"done": units, "total": units}`` in a small JSON file the
    driver polls (written atomically, at most every 0.5 s). Units: one per object processed and
    one per object whose target is built; then per task, as many for the synthesis of the batch
    (moving with its iterations) and as many again for its evaluation as the shard has objects x
    scales. A rough but steady measure of work: synthesis and evaluation dominate a shard."""

    def __init__(self, path: Path, total: float):
        self.path, self.total, self.done, self._last = path, float(total), 0.0, 0.0
        self._write(force=True)

    def add(self, n: float) -> None:
        self.set(self.done + n)

    def set(self, done: float) -> None:
        self.done = min(float(done), self.total)
        self._write(force=self.done >= self.total)

    def _write(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < 0.5:
            return
        self._last = now
        try:
            from .job import atomic_write_text

            atomic_write_text(self.path, json.dumps({"done": round(self.done, 3), "total": self.total}))
        except OSError:  # progress is a convenience: never fail a shard for it
            pass
