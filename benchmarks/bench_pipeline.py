"""Dataset pipeline benchmark -> benchmarks/results/pipeline.md.

Runs the same small job (``--scale`` procedural objects, the default JobConfig otherwise, one
object per shard) on a local Ray with one worker CPU and with two, from a warm cache: the
objects are processed and their SDF grids built before timing (CoACD and the grids are cached
across jobs; CoACD is measured by bench-objects). Reports validated (simulation-successful) grasps per core-hour, where a core-hour
is wall time x worker CPUs, the scaling ratio (throughput with two workers / with one), and the
worker seconds by stage summed from the job ledgers. Ray start-up is inside the wall time.

    python -m benchmarks.bench_pipeline [--scale 12] [--grasps N] [--default-job 2] [--grasps-sweep 4,8,16,32] [--cold 40] [--out benchmarks/results/pipeline.md]

``--default-job R`` adds the job `make dataset` runs (the default JobConfig: 6 objects, shard size
"auto") on 2 workers, warm cache, R runs alternating with the same job at the previous fixed 2 objects
per shard: validated grasps per core-hour of each, medians.

``--grasps-sweep 4,8,16,32`` adds the default job with each number of grasps per object and
scale (one run each): the fixed costs of a job and of each object are shared by more grasps.

``--ceiling N`` adds what this machine allows two workers, without Ray: N shards of the small job,
each run alone in a warm process and then as two copies at once in two processes (one torch
thread each, as a Ray worker of one CPU has). Two copies of the same work take longer than one
alone where the cores share caches and memory bandwidth; ``2 x alone / the slower copy`` is the
best 2-worker / 1-worker ratio any scheduler could reach on this machine for this work.

``--cold N`` adds the user's-scale view: N objects through a minimal config (1 grasp, 10
iterations, one start, grid 16^3, one scale) from an empty cache with 2 workers, where object
processing and the targets dominate, and its extrapolation to 5000 objects.

Twelve objects by default (~10 minutes on 2 cores for the scaling table): each of two workers
runs six shards, so the 2-worker / 1-worker ratio measures the pipeline's parallel work rather
than Ray's start-up (~4 s per job) and the last shard's tail, which weigh a third of the gap at
four objects (same session: 4 objects 1.76, 12 objects 1.88; results/pipeline.md, its table of
earlier measurements). The success counts are still small, so validated grasps per core-hour
carries a sampling error; grasps per core-hour is the steadier throughput figure.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from benchmarks.common import hand_notes, machine_description, write_report
from workers.job import JobConfig, JobDir
from workers.run import run_job



def _synth_line(cfg: "JobConfig") -> str:
    """The job's synthesis as a reader compares it: iterations and starts per grasp of its recipe."""
    r = cfg.recipes()[0].synth
    return f"{r.iters} iterations, {r.seeds_per_grasp} starts per grasp ({cfg.preset} preset)"

def _warm_cache(cfg: JobConfig, cache: str) -> None:
    from datagen.objects.manifest import build_manifest
    from datagen.objects.process import process_object

    from datagen.synth.target import GraspTarget

    pcfg = cfg.recipes()[0].process
    for e in build_manifest(cfg.source, cfg.count, cfg.scales):
        p = process_object(e.ref(), pcfg, root=cache, expected_sha256=e.sha256)
        if p.ok:  # the SDF grid cache (datagen.objects.grid_cache), as the shards' target stage reads it
            GraspTarget.from_processed(p, e.scales[0], grid_resolution=cfg.recipes()[0].grid_resolution, cache=cache)


COLD = dict(grasps_per_object=1, scales=(0.08,), grid_resolution=16, synth={"iters": 10, "seeds_per_grasp": 1})


def _cold_job(count: int, tmp: Path) -> tuple[JobConfig, float, dict]:
    """The minimal job of ``count`` objects from an empty objects cache on 2 workers."""
    cfg = JobConfig(count=count, **COLD)
    t0 = time.perf_counter()
    s = run_job(cfg, tmp / "cold", num_cpus=2, cache=str(tmp / "cold-cache"), progress=False)
    wall = time.perf_counter() - t0
    print(f"cold minimal job: {count} objects in {wall:.1f} s")
    return cfg, wall, s


def _cold_lines(cfg: JobConfig, wall: float, s: dict) -> list[str]:
    stages = {k[:-2]: v for k, v in s["stage_seconds"].items() if not k.startswith("shard_")}
    split = ", ".join(f"{k} {v:.0f} s" for k, v in stages.items())
    return ["", "## At the user's scale: a minimal config from an empty cache", "",
            f"{cfg.count} procedural objects, {cfg.grasps_per_object} grasp per object at {cfg.scales[0]} m, "
            f"synthesis {_synth_line(cfg)}, grid {cfg.recipes()[0].grid_resolution}^3, 2 workers, objects cache empty at the start "
            f"(CoACD, the SDF grids and the targets are built): {wall:.1f} s wall, {wall / cfg.count:.2f} s per "
            f"object -> `datagen run --objects 5000` with this config extrapolates to "
            f"{5000 * wall / cfg.count / 3600:.1f} h on 2 cores. Worker seconds by stage: {split}; shard CPU "
            f"{s['stage_seconds'].get('shard_cpu_s', 0.0):.0f} s.", ""]


def _timed_job(cfg: JobConfig, out: Path, cache: str | None, label: str) -> tuple[float, dict, JobConfig]:
    """(wall s, job status, the config job.json recorded) of one run of ``cfg`` on 2 workers; ``out``
    is removed afterwards."""
    t0 = time.perf_counter()
    s = run_job(cfg, out, num_cpus=2, cache=cache, progress=False)
    wall = time.perf_counter() - t0
    used = JobConfig.from_dict(json.loads((out / "job.json").read_text())["config"])
    print(f"{label}: {wall:.1f} s, {s['success']}/{s['grasps']} successful")
    shutil.rmtree(out, ignore_errors=True)
    return wall, s, used


def _shard_phase(out: Path) -> float:
    """Seconds from the first shard's start to the last shard's end (the job's ledger): the wall
    time without Ray's start-up, the workers' imports and the shutdown."""
    done = JobDir(out).finished().values()
    return max(d["finished_unix_s"] for d in done) - min(d["started_unix_s"] for d in done)


def _prepared_job(path: Path, cfg: JobConfig) -> list[dict]:
    """A job directory at ``path`` with its manifest written; the shard entries as `run_shard` takes them."""
    from workers.setup import prepare_manifest

    job = JobDir(path)
    job.lock()
    try:
        job.init(cfg)
        entries = prepare_manifest(job, cfg)
    finally:
        job.unlock()
    return [{**e.__dict__, "scales": list(e.scales)} for e in entries]


def _warm_process(_) -> int:
    import torch

    import datagen.eval  # noqa: F401 - the imports a Ray worker pays before its first shard
    import datagen.pipeline  # noqa: F401
    import workers.shard  # noqa: F401

    torch.set_num_threads(1)
    return os.getpid()


def _shard_seconds(args) -> float:
    """Wall seconds of `run_shard` ``index`` of the job at ``path`` (entries one per shard)."""
    from workers.shard import run_shard

    path, index, entries, cfg_d, cache = args
    t0 = time.perf_counter()
    run_shard(str(path), index, entries[index:index + 1], cfg_d,
              {"code_version": "bench", "packages": {}, "created_at": "bench", "cache": cache or ""})
    return time.perf_counter() - t0


def _ceiling(cfg: JobConfig, cache: str | None, tmp: Path, shards: int) -> tuple[list[str], float]:
    """(report lines, ratio ceiling) of ``--ceiling``: shards alone and as two copies at once."""
    import multiprocessing as mp

    dirs = [tmp / f"ceiling{k}" for k in (0, 1)]
    entries = [_prepared_job(d, cfg) for d in dirs]
    cfg_d = cfg.to_dict()
    n = min(shards, len(entries[0]))
    rows = []
    env = os.environ.get("OMP_NUM_THREADS")
    os.environ["OMP_NUM_THREADS"] = "1"  # inherited by the spawned processes, as Ray sets it for a 1-CPU task
    try:
        with mp.get_context("spawn").Pool(2) as pool:
            pool.map(_warm_process, [0, 1])
            last = len(entries[0]) - 1  # one untimed shard in each process: first-call costs (hand, scenes)
            pool.map(_shard_seconds, [(dirs[k], last, entries[k], cfg_d, cache) for k in (0, 1)])
            for i in range(n):
                alone = pool.apply(_shard_seconds, ((dirs[0], i, entries[0], cfg_d, cache),))
                both = pool.map(_shard_seconds, [(dirs[k], i, entries[k], cfg_d, cache) for k in (0, 1)])
                rows.append((i, alone, both))
                print(f"ceiling, shard {i}: alone {alone:.1f} s, two copies at once {both[0]:.1f} / {both[1]:.1f} s")
    finally:
        if env is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = env
    alone_sum = sum(a for _, a, _ in rows)
    slow_sum = sum(max(b) for _, _, b in rows)
    ceiling = 2 * alone_sum / slow_sum
    lines = ["", "## What this machine allows two workers (no Ray)", "",
             f"{n} shards of the job above, each run alone in a warm process, then as two copies at once in two "
             "processes (separate job directories; one torch thread each). Both processes first ran one shard "
             "untimed (imports, the hand, first calls).", "",
             "| shard | alone (s) | two at once (s) | slowdown of the slower copy |", "|---|---|---|---|"]
    for i, a, b in rows:
        lines.append(f"| {i} | {a:.1f} | {b[0]:.1f} / {b[1]:.1f} | {max(b) / a - 1:+.0%} |")
    lines += ["", f"Ceiling of the 2-worker / 1-worker ratio for this work on this machine (2 x alone / the slower "
                  f"copy, summed over the shards): **{ceiling:.2f}**. The job's ratios above stay below it by Ray's "
                  "start-up, the workers' imports and first calls, and shards of unequal length.", ""]
    return lines, ceiling


def _default_job(runs: int, cache: str | None, tmp: Path) -> list[str]:
    """The default job on 2 workers: shard size auto against 2 per shard, ``runs`` alternating runs each."""
    modes = {"auto": JobConfig(), "2 per shard (the previous default)": JobConfig(objects_per_shard=2)}
    _warm_cache(modes["auto"], cache)
    walls = {m: [] for m in modes}
    last = {}
    for r in range(runs):
        for m in (list(modes) if r % 2 == 0 else list(reversed(modes))):
            wall, s, used = _timed_job(modes[m], tmp / "default", cache, f"default job, {m}")
            walls[m].append(wall)
            last[m] = (s, used)
    cfg = modes["auto"]
    lines = ["", "## The default job (`make dataset`), 2 workers", "",
             f"The default JobConfig: {cfg.count} procedural objects at {list(cfg.scales)} m, {cfg.grasps_per_object} "
             f"grasps per object and scale, synthesis {_synth_line(cfg)}, objects cache warm; {runs} alternating runs per "
             "layout, median wall (Ray start-up included). Core-hour = wall x 2.", "",
             "| objects per shard | shards | wall (s), median | runs (s) | grasps | validated | validated / core-hour |",
             "|---|---|---|---|---|---|---|"]
    for m in modes:
        s, used = last[m]
        wall = statistics.median(walls[m])
        shards = -(-cfg.count // used.objects_per_shard)
        lines.append(f"| {m}: {used.objects_per_shard} | {shards} | {wall:.1f} | "
                     f"{', '.join(f'{w:.1f}' for w in walls[m])} | {s['grasps']} | {s['success']} | "
                     f"{s['success'] / (wall * 2 / 3600):.0f} |")
    return lines


def _grasps_sweep(values: list[int], cache: str | None, tmp: Path) -> list[str]:
    """The default job with each number of grasps per object and scale, one run each, 2 workers."""
    if not values:
        return []
    _warm_cache(JobConfig(), cache)  # the same objects whatever the grasps
    rows = []
    for g in values:
        wall, s, _ = _timed_job(JobConfig(grasps_per_object=g), tmp / f"sweep{g}", cache,
                                f"default job, {g} grasps per object")
        rows.append((g, wall, s))
    lines = ["", "## Grasps per object and scale (the default job otherwise), 2 workers", "",
             f"One run each, in this order: {', '.join(str(g) for g in values)}; objects cache warm; core-hour = wall x 2. "
             f"The default is {JobConfig().grasps_per_object}.", "",
             "| grasps per object and scale | wall (s) | grasps | validated | validated / core-hour | grasps / core-hour |",
             "|---|---|---|---|---|---|"]
    for g, wall, s in rows:
        lines.append(f"| {g} | {wall:.1f} | {s['grasps']} | {s['success']} | {s['success'] / (wall * 2 / 3600):.0f} | "
                     f"{s['grasps'] / (wall * 2 / 3600):.0f} |")
    return lines


def _commit() -> str:
    import subprocess

    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                             cwd=Path(__file__).parent)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, cwd=Path(__file__).parent).stdout.strip()
        return out.stdout.strip() + (" (with uncommitted changes)" if dirty else "")
    except OSError:
        return "unknown"


def _real(args) -> int:
    """``--real``: the real-mesh section of the report, written first in ``--out`` (other sections kept)."""
    import subprocess

    from benchmarks.common import replace_section
    from benchmarks.pipeline_real import HEADING, compare

    cache = args.cache or os.environ.get("DATAGEN_CACHE") or ""
    base = Path(args.baseline).resolve() if args.baseline else None
    base_commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=base).stdout.strip() if base else ""
    with tempfile.TemporaryDirectory(prefix="bpr-", dir="/tmp") as tmp:
        lines = compare([h for h in args.hands.split(",") if h], args.real, base, args.real_runs, cache, Path(tmp),
                        _commit(), base_commit)
    load = os.getloadavg()
    lines[1:1] = ["", f"Machine: {machine_description()}; load average at the end {load[0]:.1f} / {load[1]:.1f} / "
                      f"{load[2]:.1f}. Command: `python -m benchmarks.bench_pipeline --real {args.real} --hands "
                      f"{args.hands} --real-runs {args.real_runs}{' --baseline BASE' if base else ''}`."]
    replace_section(args.out, HEADING, lines, first=True)
    print("\n".join(lines))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=int, default=12, help="procedural objects of the scaling job (one per shard)")
    ap.add_argument("--runs", type=int, default=2, help="runs per worker count of the small job, alternating "
                    "(1, 2, 2, 1, ...); the tables quote medians")
    ap.add_argument("--grasps", type=int, default=None, help="grasps per object and scale (default: JobConfig's)")
    ap.add_argument("--grasps-sweep", default="", help="comma-separated grasps per object: the default job with "
                    "each, one run, 2 workers (e.g. 4,8,16,32)")
    ap.add_argument("--cache", default=None, help="objects cache (default $DATAGEN_CACHE)")
    ap.add_argument("--default-job", type=int, default=0, help="runs per layout of the default job (0: skip it)")
    ap.add_argument("--cold", type=int, default=0, help="objects of the cold-cache minimal job (0: skip it)")
    ap.add_argument("--ceiling", type=int, default=0, help="shards of the small job run alone and as two copies at "
                    "once without Ray (0: skip it)")
    ap.add_argument("--real", type=int, default=0, help="only the default job on the first N objects of "
                    "manifests/real_dev.jsonl, per hand of --hands, beside --baseline (benchmarks/pipeline_real.py)")
    ap.add_argument("--hands", default="leap,shadow_e3m5,allegro,shadow", help="hands of --real (comma-separated)")
    ap.add_argument("--baseline", default=None, help="root of another checkout (e.g. a git worktree of main) "
                    "run beside this one by --real")
    ap.add_argument("--real-runs", type=int, default=3, help="runs per code and hand of --real")
    ap.add_argument("--out", default="benchmarks/results/pipeline.md")
    args = ap.parse_args(argv)
    if args.real:
        return _real(args)
    cfg = JobConfig(count=args.scale, objects_per_shard=1,
                    **({"grasps_per_object": args.grasps} if args.grasps else {}))
    cache = args.cache or os.environ.get("DATAGEN_CACHE") or None
    t0 = time.perf_counter()
    _warm_cache(cfg, cache)
    print(f"objects cache warm ({time.perf_counter() - t0:.0f} s)")
    walls: dict[int, list[float]] = {1: [], 2: []}
    phases: dict[int, list[float]] = {1: [], 2: []}
    results = {}
    with tempfile.TemporaryDirectory(prefix="bp-", dir="/tmp") as tmp:
        order = [w for r in range(args.runs) for w in ((1, 2) if r % 2 == 0 else (2, 1))]
        for workers in order:  # alternating, so drift of the shared machine's load hits both alike
            out = Path(tmp) / f"w{workers}"
            t0 = time.perf_counter()
            s = run_job(cfg, out, num_cpus=workers, cache=cache, progress=False)
            wall = time.perf_counter() - t0
            walls[workers].append(wall)
            phases[workers].append(_shard_phase(out))
            results[workers] = (statistics.median(walls[workers]), s)
            print(f"{workers} worker(s): {wall:.1f} s, {s['success']}/{s['grasps']} successful")
            shutil.rmtree(out, ignore_errors=True)
        default = _default_job(args.default_job, cache, Path(tmp)) if args.default_job else []
        sweep = _grasps_sweep([int(g) for g in args.grasps_sweep.split(",") if g], cache, Path(tmp))
        cold = _cold_job(args.cold, Path(tmp)) if args.cold else None
        ceiling = _ceiling(cfg, cache, Path(tmp), args.ceiling)[0] if args.ceiling else []
    load = os.getloadavg()
    lines = ["# Dataset pipeline throughput (`make bench-pipeline`)", "",
             f"Commit {_commit()}.", "",
             f"Machine: {machine_description()}; load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} "
             "(the machine is shared: other jobs inflate the times).", "",
             f"Job: {cfg.count} procedural objects at scales {list(cfg.scales)} m, {cfg.grasps_per_object} Shadow "
             "grasps per object and scale, "
             f"task force_closure, one object per shard, synthesis {_synth_line(cfg)}, default evaluation (six "
             f"directions, 2 s hold), SDF grid {cfg.recipes()[0].grid_resolution}^3, objects cache warm. Wall time includes "
             "starting Ray.", "",
             "Core-hour = wall time x worker CPUs (the issue's measure); CPU-hour = CPU time the shard tasks "
             "actually got (less sensitive to other load on a shared machine).", "",
             f"{args.runs} alternating runs per worker count; wall = median (the runs in brackets), the other "
             "columns from the last run.", "",
             "| worker CPUs | wall (s) | grasps | validated | validated / core-hour | grasps / core-hour "
             "| shard CPU (s) | validated / CPU-hour |",
             "|---|---|---|---|---|---|---|---|"]
    rate = {}
    for w, (wall, s) in results.items():
        core_h = wall * w / 3600
        rate[w] = s["success"] / core_h
        cpu = s["stage_seconds"].get("shard_cpu_s", 0.0)
        lines.append(f"| {w} | {wall:.1f} ({', '.join(f'{x:.1f}' for x in walls[w])}) | {s['grasps']} | {s['success']} | {rate[w]:.0f} | "
                     f"{s['grasps'] / core_h:.0f} | {cpu:.1f} | {s['success'] / max(cpu, 1e-9) * 3600:.0f} |")
    thr = {w: s["success"] / wall for w, (wall, s) in results.items()}
    per_obj = results[2][0] / cfg.count  # wall s per object with 2 workers, Ray start-up included
    lines += ["", f"At the user's scale: {per_obj:.1f} s wall per object with 2 workers -> `datagen run --objects 5000` "
                  f"(this job's config) extrapolates to {5000 * per_obj / 3600:.1f} h on 2 cores (linear; the "
                  "start-up share shrinks with more objects)."]
    lines += ["", f"Scaling ratio (validated grasps per wall second, 2 workers / 1 worker): "
                  f"**{thr[2] / thr[1]:.2f}** (ideal 2.0; per-core efficiency {rate[2] / rate[1]:.0%}).",
              "", "The same ratio over the shard phase alone (first shard start to last shard end, from the "
                  "ledger; medians: "
                  + ", ".join(f"{w} worker{'s' if w > 1 else ''} {statistics.median(phases[w]):.1f} s" for w in (1, 2))
                  + f"): **{statistics.median(phases[1]) / statistics.median(phases[2]):.2f}**. The rest of each "
                  "run, "
                  + ", ".join(f"{statistics.median(walls[w]) - statistics.median(phases[w]):.1f} s with {w}"
                              for w in (1, 2))
                  + ", is Ray's start-up, the workers' first imports and the shutdown: paid once per job, it "
                  "weighs less as jobs grow.", "",
              "## Where the time goes (worker seconds, summed over shards)", "",
              "| stage | 1 worker | 2 workers |", "|---|---|---|"]
    stages = results[1][1]["stage_seconds"]
    for k in stages:
        if k.startswith("shard_"):
            continue
        lines.append(f"| {k[:-2]} | {stages[k]:.1f} | {results[2][1]['stage_seconds'].get(k, 0):.1f} |")
    lines += ["", "Stages: process = objects cache lookup (and isolated CoACD on a miss), target = the "
              "synthesis target of each object (exact SDF, hull samples, the SDF grid read from the grid cache), synth = batched optimization, eval = MuJoCo tests, "
              "write = Parquet. The rest of the wall time is Ray start-up and scheduling.", ""]
    lines += ceiling + default + sweep
    if cold is not None:
        lines += _cold_lines(*cold)
    write_report(args.out, lines + hand_notes(args.out) + [""])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
