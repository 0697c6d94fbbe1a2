"""What a job directory holds: shards done/total, grasps, success rate, failures by reason.

Stage names (in failures and timings) are those of a shard's pipeline, `STAGES`."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pyarrow.parquet as pq

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
    """Counts read from the job's ledger, shards and failure files (no Ray, no lock)."""
    from datagen.objects.manifest import load_manifest

    job = JobDir(path)
    cfg = job.config()
    n_objects = len(load_manifest(job.manifest_path, check_paths=False)) if job.manifest_path.is_file() else cfg.count
    total = len(shard_slices(n_objects, cfg.objects_per_shard))
    done = job.finished()
    grasps = success = 0
    reasons: Counter = Counter()
    failures: Counter = Counter()
    stage_s: Counter = Counter()
    if job.manifest_failures_path.is_file():
        f = pq.read_table(job.manifest_failures_path, columns=["stage", "reason"])
        failures.update(f"{s}:{r}" for s, r in zip(f["stage"].to_pylist(), f["reason"].to_pylist()))
    from .run import retryable_shards

    retryable = len(retryable_shards(job, done))
    for i, entry in done.items():
        p = job.shard_path(i)
        if p.is_file():
            t = pq.read_table(p, columns=["reason", "success"])
            grasps += t.num_rows
            success += sum(1 for x in t["success"].to_pylist() if x)
            reasons.update(t["reason"].to_pylist())
        fp = job.shard_failures_path(i)
        if fp.is_file():
            f = pq.read_table(fp, columns=["stage", "reason"])
            failures.update(f"{s}:{r}" for s, r in zip(f["stage"].to_pylist(), f["reason"].to_pylist()))
        stage_s.update(entry.get("timings", {}))
        stage_s.update({"shard_wall_s": entry.get("wall_s", 0.0), "shard_cpu_s": entry.get("cpu_s", 0.0)})
    return {"job": str(job.path), "config_hash": job.read_job()["config_hash"], "objects": n_objects,
            "shards_total": total, "shards_done": len(done), "grasps": grasps, "success": success,
            "success_rate": success / grasps if grasps else 0.0, "eval_reasons": dict(reasons.most_common()),
            "failures": dict(failures.most_common()), "stage_seconds": {k: round(v, 2) for k, v in stage_s.items()},
            "retryable": retryable, "complete": len(done) == total}


def format_status(s: dict) -> str:
    lines = [f"job {s['job']} (config {s['config_hash'][:12]})",
             f"  shards   {s['shards_done']}/{s['shards_total']}"
             + ("" if s["complete"] else "  (incomplete: rerun to resume)"),
             f"  objects  {s['objects']}",
             f"  grasps   {s['grasps']}, {s['success']} successful ({s['success_rate']:.1%})"]
    if s["eval_reasons"]:
        lines.append("  grasp outcomes: " + ", ".join(f"{k} {v}" for k, v in s["eval_reasons"].items()))
    lines.append("  failures: " + (", ".join(f"{k} {v}" for k, v in s["failures"].items()) or "none"))
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
