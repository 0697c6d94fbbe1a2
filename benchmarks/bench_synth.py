"""Synthesis benchmark: 100 Shadow force-closure grasps x 500 iterations on one object.

Reports wall time, peak memory (RSS high-water mark above the process before synthesis) and
time per iteration broken down by stage (forward + backward of each part, measured separately
on the same batch), for K = 1e2 and K = 1e4 wrench directions (the paper's hyper-parameter
table: 14.9 s / 1.5 GB and 83.5 s / 15.3 GB on an RTX 3090). Writes
``benchmarks/results/synth.md`` (``synth_cuda.md`` with ``--device cuda``, where the peak memory is
CUDA's allocator high-water mark and ``--batches`` adds a throughput-by-batch-size table). Usage:
``make bench-synth`` (``--grasps``, ``--iters``, ``--repeats``, ``--device``, ``--batches``).

``--hands shadow,leap,...`` adds the per-hand cost of the job's default synthesis (16 seeds,
300 iterations, 8 grasps on the cylinder) with the self-collision pair lists reused across
iterations (the default) and rebuilt every iteration, and each hand's cost against Shadow's.
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import statistics
import time
from pathlib import Path

import numpy as np
import torch
import trimesh

from benchmarks.common import hand_notes, machine_description, median_time
from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.tasks import load_task
from datagen.synth.energies import contact_sphere_index
from datagen.synth.penetration import sphere_penetration
from datagen.synth.init import initial_poses
from datagen.wrench import sample_directions, task_energy
from workers.job import code_version

RESULTS = Path(__file__).parent / "results" / "synth.md"


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _object(device: str = "cpu") -> GraspTarget:
    mesh = trimesh.creation.cylinder(radius=0.35, height=1.0, sections=48)
    mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))
    target = GraspTarget.from_mesh(mesh, 0.08, "cylinder")
    return target if device == "cpu" else target.to(device)


def _sync(device: str):
    """Waits for queued kernels, so that wall times cover the work (no-op on CPU)."""
    return torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)


def _peak_mb(device: str) -> float:
    """Peak memory so far: CUDA's allocator high-water mark on a GPU, the process's RSS on CPU."""
    return torch.cuda.max_memory_allocated() / 2**20 if device.startswith("cuda") else _rss_mb()


def stage_breakdown(hand, target, B: int, K: int) -> dict[str, float]:
    """ms per iteration of each stage, forward + backward, on B initial poses."""
    task = load_task("force_closure")
    dev = hand.device
    sync = _sync(str(dev))
    oi = torch.zeros(B, dtype=torch.long, device=dev)
    root, joints = initial_poses(hand, [target], oi, task.init, torch.Generator().manual_seed(0))
    dirs = sample_directions(K, generator=torch.Generator().manual_seed(1), device=dev)
    tips_idx = contact_sphere_index(hand)

    def fk():
        r = root.clone().requires_grad_(True)
        T = hand.link_transforms(r, joints)
        c, _ = hand.spheres(r, joints, transforms=T)
        c.sum().backward()

    with torch.no_grad():
        T = hand.link_transforms(root, joints)
        centres, radii = hand.spheres(root, joints, transforms=T)

    def penetration():  # the synthesis's query: only spheres that can penetrate are sampled
        c = centres.clone().requires_grad_(True)
        sphere_penetration([target], oi, c, radii).square().sum().backward()

    def contacts():
        c = centres[:, tips_idx].clone().requires_grad_(True)
        d, closest, normal = target.approx_query(c)
        (d.sum() + closest.sum() + normal.sum()).backward()

    def self_pen():
        c = centres.clone().requires_grad_(True)
        i, j = hand.self_collision_pairs[:, 0], hand.self_collision_pairs[:, 1]
        torch.relu(radii[i] + radii[j] - (c[:, i] - c[:, j]).norm(dim=-1)).square().sum().backward()

    with torch.no_grad():
        res = target.query(centres[:, tips_idx])

    def wrench():
        p = res.closest.clone().requires_grad_(True)
        n = (-res.normal).clone().requires_grad_(True)
        task_energy(p, n, 0.5, [0, 0, 0, 0, 0, 1], 180.0, dirs).sum().backward()

    def timed(fn):
        return lambda: (fn(), sync())

    return {name: 1e3 * median_time(timed(fn), repeats=7) for name, fn in
            [("FK + spheres", fk), ("penetration (grid SDF)", penetration), ("contacts (grid SDF)", contacts),
             ("self-penetration", self_pen), ("task energy (GWS)", wrench)]}


def _run(hand, target, task, cfg, B: int, sync) -> tuple[float, object]:
    t0 = time.perf_counter()
    res = synthesize(hand, [target], task, cfg, B)
    sync()
    return time.perf_counter() - t0, res


def per_hand_table(hands: list[str], target, task, dev: str, sync, repeats: int) -> list[str]:
    """Markdown lines: seconds per grasp of the job's default synthesis for each hand, with the
    self-collision pair lists reused (default) and rebuilt every iteration, alternating runs."""
    from datagen.pipeline import resolve

    B = 8
    job = resolve(hands[0], task.name).synth  # the job's default recipe (dataset preset)
    seeds, iters = job.seeds_per_grasp, job.iters
    lines = [f"## Per-hand cost, job defaults ({seeds} seeds, {iters} iterations, {B} grasps, "
             f"K = 1e2; median of {repeats} runs, settings alternating)", "",
             "| hand | spheres | self-collision pairs | s per grasp | s per grasp, pair lists rebuilt every iteration | "
             "x Shadow | poses whose pair list was rebuilt, per evaluated pose |", "|---|---|---|---|---|---|---|"]
    per_grasp = {}
    for name in hands:
        try:
            hand = load_hand(name, device=dev)
        except Exception as exc:  # noqa: BLE001 - optional hands (make hands)
            lines.append(f"| {name} | not available: {exc} | | | | | |")
            continue
        base = dataclasses.replace(job, seed=0)
        _run(hand, target, task, dataclasses.replace(base, iters=3), B, sync)  # warm-up
        times = {0.0: [], base.self_pair_skin_m: []}
        for r in range(repeats):
            for skin in times:
                times[skin].append(_run(hand, target, task, dataclasses.replace(base, seed=r, self_pair_skin_m=skin), B, sync)[0])
        counts = _rebuild_fraction(hand, target, task, base, B)
        t_list, t_fresh = (statistics.median(times[k]) / B for k in (base.self_pair_skin_m, 0.0))
        per_grasp[name] = t_list
        ratio = f"{t_list / per_grasp['shadow']:.2f}" if "shadow" in per_grasp else "-"
        lines.append(f"| {name} | {hand.num_spheres} | {hand.self_collision_pairs.shape[0]} | {t_list:.2f} | "
                     f"{t_fresh:.2f} | {ratio} | {counts:.3f} |")
        print(lines[-1], flush=True)
    return lines + ["", "Both settings give bit-identical poses (the same pairs are summed in the same order); "
                    "`tests/synth/test_self_collision.py` checks it.", ""]


def _rebuild_fraction(hand, target, task, cfg, B: int) -> float:
    """Fraction of evaluated poses whose self-collision pair list had to be made anew."""
    from datagen.synth import self_collision

    made, calls = [], []
    real = self_collision.SelfPairList.candidates

    def counting(self, centres, radii, frame):
        before = self.rebuilt
        out = real(self, centres, radii, frame)
        made.append(self.rebuilt - before)
        calls.append(centres.shape[0])
        return out

    self_collision.SelfPairList.candidates = counting
    try:
        synthesize(hand, [target], task, cfg, B)
    finally:
        self_collision.SelfPairList.candidates = real
    return sum(made) / max(1, sum(calls))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grasps", type=int, default=100)
    ap.add_argument("--iters", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--iters-k1e4", type=int, default=50, help="iterations measured at K = 1e4 (time projected to --iters)")
    ap.add_argument("--device", default="cpu", help="cpu or cuda")
    ap.add_argument("--batches", default="", help="comma-separated batch sizes for a throughput table (K = 1e2)")
    ap.add_argument("--hands", default="", help="comma-separated hands for the per-hand cost table (job defaults)")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    dev = args.device
    out = args.out or (RESULTS if dev == "cpu" else RESULTS.with_name(f"synth_{dev.split(':')[0]}.md"))
    sync = _sync(dev)
    hand = load_hand("shadow", device=dev)
    target = _object(dev)
    task = load_task("force_closure")
    where = ("CPU" if dev == "cpu" else torch.cuda.get_device_name(torch.device(dev)))
    memory = "the process's RSS high-water mark (all of Python, torch and the hand/object models included)" \
        if dev == "cpu" else "CUDA's allocator high-water mark (torch.cuda.max_memory_allocated)"
    lines = ["# Grasp synthesis benchmark (Shadow hand, force closure)", "",
             f"Machine: {machine_description()}", "", f"Commit {code_version()}.", "",
             f"{args.grasps} grasps x {args.iters} iterations on a cylinder (8 cm scale), float32, {where}. "
             f"Wall time: median of {args.repeats} runs{'' if dev == 'cpu' else ' (after one warm-up run)'}. "
             f"Peak memory: {memory} after each setting.", "",
             "| K | delta | wall time (s) | per iteration (ms) | peak memory (MB) | grasps with all tips within 5 mm | max penetration <= 2 mm |",
             "|---|---|---|---|---|---|---|"]
    base_mem = _peak_mb(dev)
    if dev != "cpu":  # CUDA context, kernels' first compilation and allocator pools: not the method's cost
        _run(hand, target, task, SynthConfig(iters=5, num_directions=100, seed=0), args.grasps, sync)
    summary = {}
    for K in (100, 10_000):
        iters = args.iters if K == 100 else args.iters_k1e4
        cfg = SynthConfig(iters=iters, num_directions=K, seed=0)
        times, res = [], None
        for r in range(args.repeats if K == 100 else 1):
            t, res = _run(hand, target, task, dataclasses.replace(cfg, seed=r), args.grasps, sync)
            times.append(t)
        wall = statistics.median(times) * args.iters / iters  # projected to args.iters when fewer were run
        contact = (res.tip_distance.abs().amax(-1) <= 0.005).float().mean().item()
        shallow = (res.max_penetration <= 0.002).float().mean().item()
        summary[K] = wall
        note = "" if iters == args.iters else f" (projected from {iters} iterations)"
        lines.append(f"| {K:.0e} | 15 | {wall:.1f}{note} | {1e3 * wall / args.iters:.0f} | {_peak_mb(dev):.0f} | "
                     f"{contact:.0%} | {shallow:.0%} |")
        print(lines[-1], flush=True)
    lines += ["", f"Memory before synthesis (models loaded): {base_mem:.0f} MB.", "",
              f"## Time per iteration by stage (B = {args.grasps}, forward + backward, ms, median of 7)", "",
              "| stage | K = 1e2 | K = 1e4 |", "|---|---|---|"]
    s100 = stage_breakdown(hand, target, args.grasps, 100)
    s1e4 = stage_breakdown(hand, target, args.grasps, 10_000)
    for name in s100:
        lines.append(f"| {name} | {s100[name]:.1f} | {s1e4[name]:.1f} |")
    lines.append(f"| sum of stages | {sum(s100.values()):.1f} | {sum(s1e4.values()):.1f} |")
    lines += ["", "The remainder of each iteration (optimizer bookkeeping, couplings, line search) is the "
              "difference between the per-iteration time above and the sum of the stages.", ""]
    batches = [int(b) for b in args.batches.split(",") if b.strip()]
    if batches:
        lines += [f"## Throughput by batch size (K = 1e2, {args.iters} iterations, one run each)", "",
                  "| grasps per batch | wall time (s) | grasps per second | peak memory (MB) |", "|---|---|---|---|"]
        for B in batches:
            if dev != "cpu":
                torch.cuda.reset_peak_memory_stats()
            t, _ = _run(hand, target, task, SynthConfig(iters=args.iters, num_directions=100, seed=0), B, sync)
            lines.append(f"| {B} | {t:.1f} | {B / t:.1f} | {_peak_mb(dev):.0f} |")
            print(lines[-1], flush=True)
        lines.append("")
    hands = [h for h in args.hands.split(",") if h.strip()]
    if hands:
        lines += per_hand_table(hands, target, task, dev, sync, args.repeats)
    verdict = f"synth: wall_K100={summary[100]:.1f}s wall_K1e4={summary[10_000]:.1f}s peak_mem={_peak_mb(dev):.0f}MB"
    lines += hand_notes(out) + ["```", verdict, "```", ""]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines))
    print(verdict)


if __name__ == "__main__":
    main()
