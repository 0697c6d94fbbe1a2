"""Many targets in one synthesis batch -> benchmarks/results/targets.md.

A shard synthesizes all its objects and scales in one batch; each target (object at a scale)
has its own SDF grid. Same number of poses, one target against 64 (the cylinder at 64 scales),
Shadow, force closure, 30 iterations, one torch thread: with the grids stacked into one query
(`datagen.synth.stacked`, the default) and with one query per target (the loop it replaces,
measured in the same run). Medians of 3 alternating runs; poses are identical in both modes.

    python -m benchmarks.bench_targets [--iters 30] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

import datagen.synth.energies as energies
import datagen.synth.penetration as penetration
from benchmarks.common import machine_description, write_report
from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.tasks import load_task
from workers.job import code_version

OUT = Path(__file__).parent / "results" / "targets.md"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iters", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    torch.set_num_threads(1)
    hand, task = load_hand("shadow"), load_task("force_closure")
    mesh = trimesh.creation.cylinder(radius=0.35, height=1.0, sections=48)
    mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))
    cases = {"1 target x 512 poses": ([GraspTarget.from_mesh(mesh, 0.08, "c", grid_resolution=32)], 512),
             "64 targets x 8 poses": ([GraspTarget.from_mesh(mesh, 0.06 + 0.0005 * k, f"c{k}", grid_resolution=32)
                                       for k in range(64)], 8)}
    cfg = SynthConfig(iters=args.iters, seed=0)
    stacked = (penetration._stacked_candidate_distance, energies.grid_query)
    modes = {"stacked grids (default)": stacked, "one query per target": (lambda *a: None, lambda *a: None)}
    times = {(c, m): [] for c in cases for m in modes}
    poses = {}
    for r in range(args.repeats):
        for m, (gd, gq) in (modes.items() if r % 2 == 0 else reversed(list(modes.items()))):
            penetration._stacked_candidate_distance, energies.grid_query = gd, gq
            for c, (targets, per) in cases.items():
                t0 = time.perf_counter()
                res = synthesize(hand, targets, task, cfg, per)
                times[(c, m)].append(time.perf_counter() - t0)
                poses.setdefault(c, []).append(res.grasp)
            print(r, m, {c: round(times[(c, m)][-1], 2) for c in cases}, flush=True)
    penetration._stacked_candidate_distance, energies.grid_query = stacked
    same = all(all(torch.equal(p, ps[0]) for p in ps) for ps in poses.values())
    lines = ["# Many targets in one synthesis batch", "", f"Machine: {machine_description()}", "",
             f"Commit {code_version()}.", "",
             f"Shadow, force closure, {args.iters} iterations, 512 poses per batch, SDF grids 32^3, one torch thread; "
             f"wall seconds, median of {args.repeats} alternating runs.", "",
             "| batch | " + " | ".join(modes) + " | stacked / per target |", "|---|---|---|---|"]
    for c in cases:
        a, b = (statistics.median(times[(c, m)]) for m in modes)
        lines.append(f"| {c} | {a:.2f} | {b:.2f} | {a / b:.2f} |")
    lines += ["", f"Poses identical across modes and runs: {'yes' if same else 'NO'}.", ""]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
