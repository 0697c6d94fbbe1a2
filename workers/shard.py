"""One shard of a job as a plain function: Ray calls `run_shard`; tests call it directly.

A shard's work is the library's: objects are processed in isolation with a time limit
(`datagen.objects.isolate`: a crashing or hanging CoACD costs that object, not the shard), then
`datagen.pipeline.run_batch` turns them into evaluated rows. What is the worker's: the job
directory (processed objects linked into it, rows naming them relative to it), the shard's
seed, progress, the shard and failure files (written atomically, with provenance metadata) and
the ledger entry. Anything that fails for an object (processing, its synthesis target, the
batch's synthesis or evaluation) becomes a `failures` row with a stage and reason.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import pickle
import shutil
import socket
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from datagen._atomic import atomic_path, atomic_write_text
from datagen.io import integrity
from datagen.pipeline import failure
from schemas import arrow_schema

from .job import JobConfig, JobDir, JobError, JobIOError, _errno_of, writing

__all__ = ["run_shard", "write_table_atomic", "shard_seed"]

_HANDS: dict = {}  # (pinned spec, its mtime, device) -> HandModel, reused by a Ray worker across shards


def shard_seed(cfg: JobConfig, index: int) -> int:
    """Synthesis seed of shard ``index`` (recorded in every row)."""
    return int(cfg.seed) + int(index)


def _link_into_job(processed, job: JobDir) -> str:
    """Hard-link (or copy) a processed-object directory into the job; returns its path
    relative to the job directory. A copy that fails (a full disk) leaves no temp dir behind
    (`JobDir.clean_temp` removes those of a killed process on the next run)."""
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

        with writing(tmp, "the processed object's copy"):
            try:
                shutil.copytree(processed.entry, tmp, copy_function=link)
            except shutil.Error as exc:  # copytree gathers the errors of its files: the first one
                shutil.rmtree(tmp, ignore_errors=True)
                first = exc.args[0][0] if exc.args and exc.args[0] else ("", "", str(exc))
                raise OSError(_errno_of(first[2]), str(first[2]), first[1]) from None
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
        try:
            os.replace(tmp, dst)
        except OSError:  # another attempt won the race
            shutil.rmtree(tmp, ignore_errors=True)
    return str(rel)


def write_table_atomic(table: pa.Table, path: Path) -> dict:
    """Write Parquet atomically (`datagen._atomic`) with page checksums: the final name holds
    either nothing or a complete file. Returns its ledger record (`integrity.file_record`).
    A write that fails (a full disk) is a `JobIOError` naming the path; no temp file is left."""
    with writing(path, "the Parquet file"):
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp, **integrity.WRITE_OPTIONS)
            record = integrity.file_record(tmp)
    return record


def _failure(fails: list, shard: int, object_id: str, stage: str, reason: str, message: str,
             scale: float = float("nan"), task: str = "") -> None:
    """Append a `failures` row of shard ``shard`` (`datagen.pipeline.failure` plus the shard)."""
    fails.append({**failure(object_id, stage, reason, message, scale, task), "shard": shard})


def _hand(name: str, job: JobDir, device: str):
    """The job's hand: the copy pinned in the job directory (``hands/<name>.yaml``), else (a job
    made before hands were pinned) ``name`` as the config gives it. Reused by a Ray worker while
    the pinned file is unchanged."""
    from datagen.hands import hand_spec_path, load_hand

    path = hand_spec_path(name, job.path)
    key = (str(path), path.stat().st_mtime_ns if path.is_file() else 0, device)
    if key not in _HANDS:
        _HANDS[key] = load_hand(name, device=device, base=job.path)
    return _HANDS[key]


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


def same_recipes(job: JobDir, recipes: list) -> list:
    """``recipes`` (this worker's code resolving the job's config), checked against the resolved
    recipes job.json recorded when the job started: a worker whose code resolves them differently
    (code edited mid-job, a cluster node on another version) would write rows the job does not
    describe, so it stops the shard with `JobError` naming both."""
    recorded = job.read_job().get("recipes")
    mine = json.loads(json.dumps([r.to_dict() for r in recipes]))
    if recorded is not None and recorded != mine:
        diff = sorted(f"{t}.{k}" for t, (a, b) in enumerate(zip(recorded, mine))
                      for k in set(a) | set(b) if a.get(k) != b.get(k))
        raise JobError(f"job {job.path}: this worker's code resolves the job's settings differently from "
                       f"job.json's recipes (differing: {', '.join(diff) or 'the task list'})",
                       "run every node on the code version that started the job (job.json `code_version`)")
    return recipes


def _node_id() -> str:
    """The Ray node this shard runs on ("" outside Ray): `datagen status` shows where shards ran."""
    try:
        import ray

        return ray.get_runtime_context().get_node_id() if ray.is_initialized() else ""
    except Exception:  # noqa: BLE001 - provenance only
        return ""


def _idle_cores():
    """On a one-node Ray cluster (the local one of ``make dataset``), a function giving how many of
    its CPUs no task holds now (asked at most once a second); None outside Ray or on a cluster of
    several nodes (an idle CPU there may be on another machine). When a job's other shards have
    finished and none waits, the evaluation steps its directions on the freed core
    (`datagen.eval.Evaluator`, ``spare_cores``). A shard run in-process without Ray installed
    (`benchmarks/cuda_shards.py`) has none."""
    try:
        import ray
    except ImportError:
        return None

    try:
        if not ray.is_initialized() or sum(bool(n.get("Alive")) for n in ray.nodes()) != 1:
            return None
    except Exception:  # noqa: BLE001 - no answer: evaluate as before, on this core
        return None
    last = {"t": -math.inf, "idle": 0}

    def idle() -> int:
        now = time.monotonic()
        if now - last["t"] >= 1.0:
            try:
                idle_now = int(ray.available_resources().get("CPU", 0))
            except Exception:  # noqa: BLE001 - a question about spare cores never fails a grasp
                idle_now = 0
            last["t"], last["idle"] = now, idle_now
        return last["idle"]
    return idle


def _run_shard(job_path: str, index: int, entries: list[dict], cfg_dict: dict, provenance: dict) -> dict:
    import torch

    from datagen.pipeline import run_batch

    t_start, cpu_start, started = time.perf_counter(), time.process_time(), time.time()
    job = JobDir(job_path)
    cfg = JobConfig.from_dict(cfg_dict)
    recipes = same_recipes(job, cfg.recipes())
    torch.set_num_threads(max(1, int(cfg.cpus_per_shard)))
    device = "cuda" if torch.cuda.is_available() else "cpu"
    cache = provenance.get("cache") or None
    n_targets = sum(len(d["scales"]) for d in entries)
    progress = ShardProgress(job.progress_path(index), total=2 * len(entries) + 2 * len(cfg.tasks) * n_targets,
                             node=_node_id())
    timings = {"process_s": 0.0, "observe_s": 0.0, "target_s": 0.0, "synth_s": 0.0, "eval_s": 0.0, "write_s": 0.0}
    fails: list[dict] = []

    # 1. objects: processed in isolation, linked into the job directory (the tasks share the processing)
    t0 = time.perf_counter()
    ready = _ready_objects(entries, recipes[0].process, cache, cfg, job, index, fails, progress)
    timings["process_s"] = time.perf_counter() - t0

    # 1b. what a learner sees of each object and scale (isolated too: the renderer is native code)
    t0 = time.perf_counter()
    observations = _observe(ready, cfg, index, fails) if cfg.observations.enabled else None
    timings["observe_s"] = time.perf_counter() - t0

    # 2-4. synthesis targets, synthesis per task, MuJoCo evaluation (datagen.pipeline)
    hand = _hand(provenance.get("hand") or cfg.hand, job, device)

    def moved(done: float, total: float) -> None:
        progress.total = len(entries) + total
        progress.set(len(entries) + done)

    batch = run_batch(ready, hand, recipes, grasps_per_object=cfg.grasps_per_object,
                      seed=shard_seed(cfg, index), cache=cache, base=job.path,
                      device=device, progress=moved, eval_workers=max(1, int(cfg.cpus_per_shard)),
                      eval_spare_cores=_idle_cores())
    for f in batch.failures:
        fails.append({**f, "shard": index})
    timings.update(batch.timings)

    # 5. write: shard (if it has rows), failures, then the ledger entry
    t0 = time.perf_counter()
    meta = _shard_metadata(hand, cfg, recipes, provenance, index)
    out = batch.rows.replace_schema_metadata(meta)
    files = _write_shard_files(job, index, out, observations, fails, cfg, provenance)
    timings["write_s"] = time.perf_counter() - t0
    n_ok = int(pc.sum(out["success"]).as_py() or 0) if out.num_rows else 0
    summary = {"shard": index, "objects": len(entries), "objects_ok": len(ready), "grasps": out.num_rows,
               "observations": observations.num_rows if observations is not None else 0,
               "success": n_ok, "failures": len(fails), "host": socket.gethostname(), "device": device,
               "timings": {k: round(v, 3) for k, v in timings.items()},
               "wall_s": round(time.perf_counter() - t_start, 3),
               "started_unix_s": round(started, 3), "finished_unix_s": round(time.time(), 3),
               "cpu_s": round(time.process_time() - cpu_start, 3),  # this process (not the CoACD children)
               "node": _node_id(), "seed": shard_seed(cfg, index), "config_hash": cfg.hash(),
               "objects_per_shard": cfg.objects_per_shard, "files": files}
    job.record_finished(index, summary)
    progress.set(progress.total)
    return summary


def _ready_objects(entries: list[dict], pcfg, cache, cfg: JobConfig, job: JobDir, index: int, fails: list,
                   progress: ShardProgress) -> list:
    """The shard's objects processed in isolation (``datagen.objects.isolate``) and linked into the
    job directory, as ``BatchObject``s with the manifest's id, hash and scales and the object's path
    relative to the job directory; an object that fails is a row of ``fails`` and is left out."""
    from datagen.objects.errors import ObjectError
    from datagen.objects.isolate import process_isolated
    from datagen.objects.manifest import ManifestEntry, resolve_scales
    from datagen.objects.process import load_processed
    from datagen.pipeline import BatchObject

    ready = []
    for d in entries:
        e = ManifestEntry(**{**d, "scales": tuple(d["scales"])})
        try:
            p = process_isolated(e, pcfg, cache, cfg.object_timeout_s,
                                 remedy="raise object_timeout_s and rerun with --retry-failed")
            if not p.ok:
                _failure(fails, index, e.id, "process", p.reason, p.message)
                continue
            rel = _link_into_job(p, job)
            processed = load_processed(job.path / rel)
            ready.append(BatchObject(processed, resolve_scales(e.scales, processed.factor, e.id), object_id=e.id,
                                     object_path=rel, mesh_sha256=e.sha256, split=e.split))
        except ObjectError as exc:  # e.g. scale "native" on a mesh that is not in metres
            _failure(fails, index, e.id, "process", exc.reason.value, str(exc))
        except JobIOError:  # the job directory cannot be written (a full disk): the shard stops
            raise
        except Exception as exc:  # noqa: BLE001 - recorded, never fatal
            _failure(fails, index, e.id, "process", "error", f"{e.id}: {type(exc).__name__}: {exc}")
        finally:
            progress.add(1)
    return ready


def _shard_metadata(hand, cfg: JobConfig, recipes: list, provenance: dict, index: int) -> dict:
    """The shard file's Parquet metadata: the evaluated schema's, plus the joint names, the
    provenance, the shard's seed and every recipe with that seed."""
    seed = shard_seed(cfg, index)
    meta = dict(arrow_schema("evaluated", nq=7 + hand.num_joints).metadata)
    meta.update({k.encode(): (v if isinstance(v, str) else json.dumps(v, sort_keys=True)).encode() for k, v in {
        "datagen.joint_names": hand.joint_names, "datagen.code_version": provenance["code_version"],
        "datagen.config_hash": cfg.hash(), "datagen.packages": provenance["packages"],
        "datagen.host": socket.gethostname(), "datagen.job_created_at": provenance["created_at"],
        "datagen.written_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "datagen.shard": str(index), "datagen.seed": str(seed),
        "datagen.recipes": [dataclasses.replace(r, synth=dataclasses.replace(r.synth, seed=seed)).to_dict()
                            for r in recipes],
        "datagen.synth_config": dataclasses.replace(recipes[0].synth, seed=seed).to_dict(),
        "datagen.eval_config": recipes[0].eval.to_dict(),
        "datagen.process_config": recipes[0].process.to_dict()}.items()})
    return meta


def _write_shard_files(job: JobDir, index: int, out: pa.Table, observations, fails: list, cfg: JobConfig,
                       provenance: dict) -> dict:
    """Writes the shard's rows (if any), its observations (if any) and its failures, each
    atomically; returns the ledger's record of each file (size, rows, sha256: readers check them)."""
    files = {}
    if out.num_rows:
        files[integrity.shard_file(index)] = write_table_atomic(out, job.shard_path(index))
    else:  # no rows: no shard file (some readers, e.g. Hugging Face datasets, reject empty Parquet files)
        job.shard_path(index).unlink(missing_ok=True)
    if observations is not None and observations.num_rows:
        obs_meta = {**dict(observations.schema.metadata), **{k.encode(): v.encode() for k, v in {
            "datagen.observation_config": json.dumps(cfg.observations.to_dict(), sort_keys=True),
            "datagen.code_version": provenance["code_version"], "datagen.config_hash": cfg.hash(),
            "datagen.shard": str(index)}.items()}}
        files[integrity.observations_file(index)] = write_table_atomic(observations.replace_schema_metadata(obs_meta),
                                                                       job.observations_path(index))
    else:
        job.observations_path(index).unlink(missing_ok=True)
    files[integrity.failures_file(index)] = write_table_atomic(
        pa.Table.from_pylist(fails, schema=arrow_schema("failures")), job.shard_failures_path(index))
    return files


def _observe(ready: list, cfg: JobConfig, index: int, fails: list):
    """The ``observations`` table of the shard's processed objects at their scales
    (`datagen.objects.observations`, each object in a worker process with the object time
    limit); an object that cannot be observed is a failure row (stage ``observe``) and keeps its
    grasps."""
    from datagen.gl import GLUnavailable
    from datagen.objects.observations import ObservationError, observation_table, observe_isolated

    rows: list[dict] = []
    for o in ready:
        try:
            rows += observe_isolated(o.processed, o.scales, cfg.observations, cfg.seed, cfg.object_timeout_s,
                                     object_id=o.object_id, object_path=o.object_path, split=o.split,
                                     mesh_sha256=o.mesh_sha256)
        except ObservationError as exc:
            _failure(fails, index, o.object_id, "observe", exc.reason, str(exc))
        except GLUnavailable as exc:  # this node renders nothing: every object says so
            _failure(fails, index, o.object_id, "observe", "no_gl", f"{o.object_id}: {exc}")
    return observation_table(rows)


class ShardProgress:
    """A running shard's progress, ``{"done": units, "total": units, "node": Ray node id}`` in a small JSON file the
    driver polls (written atomically, at most every 0.5 s). Units: one per object processed and
    one per object whose target is built; then per task, as many for the synthesis of the batch
    (moving with its iterations) and as many again for its evaluation as the shard has objects x
    scales. A rough but steady measure of work: synthesis and evaluation dominate a shard."""

    def __init__(self, path: Path, total: float, node: str = ""):
        self.path, self.total, self.done, self._last, self.node = path, float(total), 0.0, 0.0, node
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
            self.path.parent.mkdir(parents=True, exist_ok=True)
            # polled, rewritten every 0.5 s: atomic but not flushed to disk
            state = {"done": round(self.done, 3), "total": self.total, "node": self.node}
            atomic_write_text(self.path, json.dumps(state), fsync=False)
        except OSError:  # progress is a convenience: never fail a shard for it
            pass
