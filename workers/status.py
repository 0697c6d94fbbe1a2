"""What a job directory holds: shards done/total, grasps, success rate, failures by reason.

Stage names (in failures and timings) are those of a shard's pipeline, `STAGES`."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from .job import JobDir, shard_slices

__all__ = ["STAGES", "job_status", "format_status"]

# stage -> what it does (a failure's `stage` column and the timings use these names)
STAGES = {
    "manifest": "enumerating the source: the object could not be a manifest entry",
    "process": "mesh checks, repair, normalization and CoACD convex decomposition (cached per mesh)",
    "target": "the synthesis target: signed-distance grid and hull samples of the object",
    "synth": "grasp synthesis (the wrench-space optimization), one batch per shard and task",
    "eval": "MuJoCo hold test of every grasp",
    "write": "writing the Parquet shard, its failures and ledger entry",
}


def job_status(path: str | Path) -> dict:
    """Counts read from the job's ledger, shards and failure files (no Ray, no lock). Every
    finished shard's files are checked against its ledger entry (size and footer row count,
    `JobDir.audit`): one that does not match is not counted and is listed in ``damaged``
    (index -> the file and what is wrong); a rerun of the job redoes it."""
    from datagen.io.integrity import ShardError, read_parquet
    from datagen.objects.manifest import load_manifest

    job = JobDir(path)
    cfg = job.config()
    n_objects = len(load_manifest(job.manifest_path, check_paths=False)) if job.manifest_path.is_file() else cfg.count
    total = len(shard_slices(n_objects, cfg.objects_per_shard))
    found = job.audit()
    done, damaged = dict(found.finished), dict(found.problems)
    grasps = success = 0
    reasons: Counter = Counter()
    failures: Counter = Counter()
    stage_s: Counter = Counter()
    if job.manifest_failures_path.is_file():
        f = read_parquet(job.manifest_failures_path, ["stage", "reason"])
        failures.update(f"{s}:{r}" for s, r in zip(f["stage"].to_pylist(), f["reason"].to_pylist()))
    from .finished import retryable_shards

    for i, entry in sorted(done.items()):
        p, fp = job.shard_path(i), job.shard_failures_path(i)
        try:
            t = read_parquet(p, ["reason", "success"]) if i in found.shard_files(job.path) else None
            f = read_parquet(fp, ["stage", "reason"]) if fp.is_file() else None
        except ShardError as exc:
            damaged[i] = f"{Path(exc.path).relative_to(job.path)}: {exc.reason}"
            continue
        if t is not None:
            grasps += t.num_rows
            success += sum(1 for x in t["success"].to_pylist() if x)
            reasons.update(t["reason"].to_pylist())
        if f is not None:
            failures.update(f"{s}:{r}" for s, r in zip(f["stage"].to_pylist(), f["reason"].to_pylist()))
        stage_s.update(entry.get("timings", {}))
        stage_s.update({"shard_wall_s": entry.get("wall_s", 0.0), "shard_cpu_s": entry.get("cpu_s", 0.0)})
    for i in damaged:
        done.pop(i, None)
    retryable = len(retryable_shards(job, done))
    return {"job": str(job.path), "config_hash": job.read_job()["config_hash"], "objects": n_objects,
            "shards_total": total, "shards_done": len(done), "grasps": grasps, "success": success,
            "success_rate": success / grasps if grasps else 0.0, "eval_reasons": dict(reasons.most_common()),
            "failures": dict(failures.most_common()), "stage_seconds": {k: round(v, 2) for k, v in stage_s.items()},
            "retryable": retryable, "damaged": {int(k): v for k, v in sorted(damaged.items())},
            "nodes": len({e.get("node") for e in done.values() if e.get("node")}),
            "complete": len(done) == total}


def format_status(s: dict) -> str:
    lines = [f"job {s['job']} (config {s['config_hash'][:12]})",
             f"  shards   {s['shards_done']}/{s['shards_total']}"
             + ("" if s["complete"] else "  (incomplete: rerun to resume)"),
             f"  objects  {s['objects']}",
             f"  grasps   {s['grasps']}, {s['success']} successful ({s['success_rate']:.1%})"]
    if s["eval_reasons"]:
        lines.append("  grasp outcomes: " + ", ".join(f"{k} {v}" for k, v in s["eval_reasons"].items()))
    lines.append("  failures: " + (", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "none"))
    for i, why in s.get("damaged", {}).items():
        lines.append(f"  shard {i} is not counted: {why}")
    if s.get("damaged"):
        lines.append(f"  rerun the job to redo {len(s['damaged'])} damaged shard(s) (same seeds, same rows): "
                     f"datagen run --resume --out {s['job']}")
    if s.get("retryable"):
        lines.append(f"  {s['retryable']} shard(s) have failures a rerun may fix: rerun with --retry-failed")
    if s["stage_seconds"]:
        lines.append("  worker seconds by stage: " + ", ".join(f"{k[:-2]} {v:.1f}" for k, v in
                                                               s["stage_seconds"].items()))
    used = {k.split(":")[0] for k in s["failures"]} | {k[:-2] for k in s["stage_seconds"]}
    legend = [f"{k} = {v}" for k, v in STAGES.items() if k in used]
    if legend:
        lines.append("  stages: " + "; ".join(legend))
    if s.get("shard_errors"):
        lines.append("  shard errors: " + "; ".join(f"{k}: {v}" for k, v in s["shard_errors"].items()))
    return "\n".join(lines)
