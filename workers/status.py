"""What a job directory holds: shards done/total, grasps, success rate, failures by reason.

Stage names (in failures and timings) are those of a shard's pipeline, `STAGES`."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

from .job import JobDir, JobError, shard_slices

__all__ = ["STAGES", "format_diversity", "format_status", "job_diversity", "job_status"]

# stage -> what it does (a failure's `stage` column and the timings use these names)
STAGES = {
    "manifest": "enumerating the source: the object could not be a manifest entry",
    "process": "mesh checks, repair, normalization and CoACD convex decomposition (cached per mesh)",
    "observe": "the object observations: surface points, depth images from the cameras (observations/)",
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
    observations = sum(int(e.get("observations", 0)) for e in done.values())
    retryable = len(retryable_shards(job, done))
    return {"job": str(job.path), "config_hash": job.read_job()["config_hash"], "objects": n_objects,
            "shards_total": total, "shards_done": len(done), "grasps": grasps, "success": success,
            "observations": observations,
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
    if s.get("observations"):
        lines.append(f"  observations  {s['observations']} objects x scales (observations/: point clouds, "
                     "camera views)")
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


def _finite(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def job_diversity(path: str | Path) -> list[dict]:
    """The diversity of a job's successful grasps (`datagen.eval.diversity`) per task and scale,
    and per task over every scale (``object_scale_m`` None): ``[{"hand", "task", "object_scale_m",
    "n", "pca": [top 1..5 cumulative explained-variance ratios], "joint_entropy": nats}]`` (None
    where undefined: fewer than 2 grasps for the PCA, none for the entropy). The joint limits are
    the job's hand's (its pinned copy, `load_hand`); raises `JobError` naming the hand when it
    cannot be loaded here, `ShardError` for a damaged shard."""
    import numpy as np

    from datagen.eval.diversity import grouped_diversity
    from datagen.hands import HandSpecError, load_hand
    from datagen.io import read_job

    job = JobDir(path)
    cfg = job.config()
    t = read_job(job.path, columns=["grasp_qpos", "task", "object_scale_m"], only_success=True)
    try:
        hand = load_hand(cfg.hand, base=job.path)
    except (HandSpecError, OSError, ValueError, KeyError) as exc:
        raise JobError(f"job {job.path}: the diversity needs the joint limits of hand {cfg.hand!r}, which "
                       f"cannot be loaded here ({' '.join(str(exc).split())})", "run `make hands`") from None
    lo, hi = hand.joint_lower.cpu().numpy(), hand.joint_upper.cpu().numpy()
    q = np.asarray(t["grasp_qpos"].combine_chunks().flatten().to_numpy(zero_copy_only=False),
                   np.float64).reshape(t.num_rows, -1) if t.num_rows else np.zeros((0, 7 + len(lo)))
    tasks, scales = t["task"].to_pylist(), [round(float(x), 6) for x in t["object_scale_m"].to_pylist()]
    out = []
    for by_scale in (True, False):
        keys = [(k, s if by_scale else math.inf) for k, s in zip(tasks, scales)]
        for (task, scale), d in grouped_diversity(q, keys, lo, hi):
            out.append({"hand": cfg.hand, "task": task, "object_scale_m": None if scale == math.inf else scale,
                        "n": d.n, "pca": [_finite(x) for x in d.pca], "joint_entropy": _finite(d.joint_entropy)})
    return sorted(out, key=lambda r: (r["task"], r["object_scale_m"] is None, r["object_scale_m"] or 0.0))


DIVERSITY_LEGEND = ("PCA: cumulative explained-variance ratio of the top 1..5 principal components of "
                    "[root translation, root axis-angle, joints] (DexGraspBench; lower = more diverse); entropy: "
                    "mean over joints of the 32-bin histogram entropy over the joint limits (GraspQP; nats, "
                    "max ln 32 = 3.47)")


def format_diversity(rows: list[dict]) -> str:
    """`job_diversity` as the lines of ``datagen status --diversity``."""
    lines = ["  diversity of the successful grasps:",
             f"    {'hand':<12} {'task':<20} {'scale m':>8} {'grasps':>6}  {'PCA top 1 / 2 / 3 / 4 / 5':<32} entropy"]
    for r in rows:
        scale = "all" if r["object_scale_m"] is None else f"{r['object_scale_m']:g}"
        pca = " / ".join("  - " if x is None else f"{x:.2f}" for x in r["pca"])
        ent = "-" if r["joint_entropy"] is None else f"{r['joint_entropy']:.2f}"
        lines.append(f"    {r['hand']:<12} {r['task']:<20} {scale:>8} {r['n']:>6}  {pca:<32} {ent}")
    if not rows:
        lines.append("    no successful grasps")
    lines.append("  " + DIVERSITY_LEGEND)
    return "\n".join(lines)
