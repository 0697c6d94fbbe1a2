"""Isolated object processing: a worker interpreter reused across objects against a fresh one per
object -> benchmarks/results/isolation.md.

The job's processing (the `dataset` preset's, CoACD seeded) of N procedural objects, each
through `datagen.objects.isolate.process_isolated`, serially, from an empty cache: once with
the workers reused (the default, `isolated_worker.MAX_TASKS` objects each) and once with a fresh
worker interpreter per object (``MAX_TASKS = 1``, the cost of per-object isolation before the
workers were reused). Alternating runs, medians. The processed pieces of both modes are compared
byte for byte.

    python -m benchmarks.bench_isolation [--objects 12] [--repeats 3]
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import tempfile
import time
from pathlib import Path

from benchmarks.common import machine_description, write_report
from datagen.objects import isolated_worker
from datagen.objects.isolate import process_isolated
from datagen.objects.manifest import build_manifest
from workers.job import JobConfig, code_version

OUT = Path(__file__).parent / "results" / "isolation.md"


def _digest(cache: Path) -> str:
    """Hash of every processed file but the metadata (which holds timings)."""
    h = hashlib.sha256()
    for p in sorted(cache.rglob("*")):
        if p.is_file() and p.suffix != ".json" and "objects" in p.parts:
            h.update(str(p.relative_to(cache)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _run(entries, pcfg, max_tasks: int) -> tuple[float, list[float], str]:
    old = isolated_worker.MAX_TASKS
    isolated_worker.MAX_TASKS = max_tasks
    try:
        with tempfile.TemporaryDirectory(prefix="bench-isolation-") as cache:
            per = []
            t0 = time.perf_counter()
            for e in entries:
                t = time.perf_counter()
                p = process_isolated(e, pcfg, cache, 300)
                if not p.ok:
                    raise RuntimeError(f"{e.id}: {p.message}")
                per.append(time.perf_counter() - t)
            return time.perf_counter() - t0, per, _digest(Path(cache))
    finally:
        isolated_worker.MAX_TASKS = old
        isolated_worker._shutdown()  # each run starts without an idle worker


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=12)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    cfg = JobConfig(count=args.objects)
    pcfg = cfg.recipes()[0].process
    entries = build_manifest(cfg.source, cfg.count, cfg.scales)
    modes = {"reused worker (default)": isolated_worker.MAX_TASKS, "fresh interpreter per object": 1}
    walls = {m: [] for m in modes}
    pers = {m: [] for m in modes}
    digests = set()
    for r in range(args.repeats):
        for m, k in (modes.items() if r % 2 == 0 else reversed(list(modes.items()))):
            wall, per, digest = _run(entries, pcfg, k)
            walls[m].append(wall)
            pers[m] += per
            digests.add(digest)
            print(f"{m}: {wall:.1f} s", flush=True)
    base = statistics.median(walls["fresh interpreter per object"])
    lines = ["# Isolated object processing: reused worker against a fresh interpreter per object", "",
             f"Machine: {machine_description()}", "", f"Commit {code_version()}.", "",
             f"{args.objects} procedural objects, the job's processing config (the dataset preset's), serial, empty cache "
             f"each run; {args.repeats} alternating runs per mode, medians.", "",
             "| mode | wall for all objects (s) | runs (s) | per object, median (s) | x fresh |", "|---|---|---|---|---|"]
    for m in modes:
        w = statistics.median(walls[m])
        lines.append(f"| {m} | {w:.1f} | {', '.join(f'{x:.1f}' for x in walls[m])} | "
                     f"{statistics.median(pers[m]):.2f} | {w / base:.2f} |")
    lines += ["", f"Processed pieces identical in every run: {'yes' if len(digests) == 1 else 'NO'}.", ""]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
