"""The default job on the real-object set, this code beside another checkout's, in one run
(`bench_pipeline --real N`) -> a section of benchmarks/results/pipeline.md.

Each run is the job `datagen run --manifest manifests/real_dev.jsonl --objects N --hand H` makes
(the default JobConfig otherwise: force closure, 16 grasps per object and scale at the manifest's
0.06 / 0.08 / 0.10 m, shard size auto) on a local Ray with 2 CPUs, from a warm objects cache, in
a subprocess whose ``PYTHONPATH`` is the code's root (so ``--baseline DIR``, e.g. a `git worktree`
of main, runs its own library and workers with this checkout's environment). Runs alternate
between the codes (this, baseline, baseline, this, ...) per hand, so drift of a shared machine's
load hits both alike; the table quotes medians. Validated grasps per core-hour = successes /
(wall x 2 CPUs); per CPU-hour = successes / the shard processes' own CPU seconds (less sensitive
to other load). The worker seconds by stage are summed from the job's ledger (medians over runs);
the synthesis and evaluation splits inside them are `benchmarks/results/pipeline.md`'s profile.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = "manifests/real_dev.jsonl"
HEADING = "## The default job on real meshes (`make bench-pipeline-real`)"

# run in the code's own root: the job, then its status (both codes have these functions)
_CHILD = """
import json, sys
from workers.job import JobConfig
from workers.run import run_job
cfg = JobConfig(manifest=sys.argv[1], count=int(sys.argv[2]), hand=sys.argv[3])
s = run_job(cfg, sys.argv[4], num_cpus=2, cache=sys.argv[5] or None, progress=False, log=lambda *a: None)
print("STATUS " + json.dumps({k: s[k] for k in ("grasps", "success", "stage_seconds")}))
"""


def _run(code: Path, hand: str, count: int, out: Path, cache: str) -> dict:
    """One job of ``code`` (its root): wall seconds and the job's status figures."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", _CHILD, str(ROOT / MANIFEST), str(count), hand, str(out), cache],
                       cwd=code, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode:
        raise RuntimeError(f"job of {code} ({hand}) failed:\n{p.stderr[-3000:]}")
    line = next(x for x in p.stdout.splitlines() if x.startswith("STATUS "))
    s = json.loads(line[len("STATUS "):])
    shutil.rmtree(out, ignore_errors=True)
    return {"wall": wall, **s}


def _warm(count: int, cache: str) -> None:
    """The manifest's first ``count`` objects processed, their SDF grids and their convex pieces'
    grids (the power grasps' penetration terms) built before timing."""
    from datagen.objects.manifest import load_manifest
    from datagen.objects.process import process_object
    from datagen.synth.target import GraspTarget
    from workers.job import JobConfig

    rec = JobConfig(manifest=str(ROOT / MANIFEST), count=count).recipes()[0]
    for e in load_manifest(ROOT / MANIFEST)[:count]:
        p = process_object(e.ref(), rec.process, root=cache or None, expected_sha256=e.sha256)
        if p.ok:
            GraspTarget.from_processed(p, 0.08, grid_resolution=rec.grid_resolution, cache=cache or None).pieces()


def compare(hands: list[str], count: int, baseline: Path | None, runs: int, cache: str, tmp: Path,
            commit: str, base_commit: str) -> list[str]:
    """Run the jobs and return the report section's lines; a hand written ``NAME:R`` gets R runs
    per code instead of ``runs``."""
    codes = {"this": ROOT} | ({"baseline": baseline} if baseline else {})
    want = {h.partition(":")[0]: int(h.partition(":")[2] or runs) for h in hands}
    hands = list(want)
    _warm(count, cache)
    res: dict = {(h, c): [] for h in hands for c in codes}
    for r in range(max(want.values())):
        for h in [h for h in hands if want[h] > r]:
            for c in (list(codes) if r % 2 == 0 else list(reversed(codes))):
                s = _run(codes[c], h, count, tmp / f"{h}-{c}-{r}", cache)
                res[(h, c)].append(s)
                print(f"{h}, {c}, run {r}: {s['wall']:.1f} s, {s['success']}/{s['grasps']} validated, "
                      f"stages {json.dumps(s['stage_seconds'])}", flush=True)
    label = {"this": f"this ({commit})", "baseline": f"baseline ({base_commit})"}
    lines = [HEADING, "",
             f"`datagen run --manifest {MANIFEST} --objects {count} --hand H` (the default JobConfig otherwise: "
             "force closure, 16 grasps per object and scale at 0.06 / 0.08 / 0.10 m, shard size auto), 2 worker "
             f"CPUs, warm objects cache, runs per code and hand ({', '.join(f'{h} {n}' for h, n in want.items())}) alternating; wall = median (runs in "
             "brackets), Ray start-up included. Core-hour = wall x 2; CPU-hour = the shards' own CPU time.", "",
             "| hand | code | wall (s) | grasps | validated | validated / core-hour | shard CPU (s) | validated / CPU-hour |",
             "|---|---|---|---|---|---|---|---|"]
    for h in hands:
        for c in codes:
            rs = res[(h, c)]
            wall = statistics.median(x["wall"] for x in rs)
            cpu = statistics.median(x["stage_seconds"].get("shard_cpu_s", 0.0) for x in rs)
            ok, n = rs[-1]["success"], rs[-1]["grasps"]
            lines.append(f"| {h} | {label[c]} | {wall:.1f} ({', '.join(format(x['wall'], '.1f') for x in rs)}) | {n} | {ok} | "
                         f"{ok / (wall * 2 / 3600):.0f} | {cpu:.1f} | {ok / max(cpu, 1e-9) * 3600:.0f} |")
    stages = sorted({k for rs in res.values() for x in rs for k in x["stage_seconds"] if not k.startswith("shard_")})
    lines += ["", "Worker seconds by stage (medians over the runs, summed over the shards):", "",
              "| hand | code | " + " | ".join(k[:-2] for k in stages) + " |", "|---|---|" + "---|" * len(stages)]
    for h in hands:
        for c in codes:
            rs = res[(h, c)]
            lines.append(f"| {h} | {label[c]} | " + " | ".join(
                f"{statistics.median(x['stage_seconds'].get(k, 0.0) for x in rs):.1f}" for k in stages) + " |")
    same = [h for h in hands if len(codes) > 1 and
            all(a["success"] == b["success"] for a, b in zip(res[(h, "this")], res[(h, "baseline")]))]
    if len(codes) > 1:
        lines += ["", "Validated grasps equal between the codes in every run: " + (", ".join(same) or "none") + "."]
    return lines + [""]
