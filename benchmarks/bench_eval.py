"""Evaluation cost: the project's evaluator against the peer benchmark's loop, same grasps -> eval.md.

CPU seconds per grasp (process time, one thread) of, on the same grasps and in one run:

* ``project (default)``: `datagen.eval.Evaluator` with the default `EvalConfig`: ``hand_root:
  spec`` (the forearm and driven wrist joints), the closing simulated once and copied per
  direction, directions in lockstep, stop at the first failing check, and the early pass
  (``settle_checks`` 2, ``settle_safety`` 12: a passing direction stops once its creep has
  settled, see datagen/eval/hold.py); static metrics and epsilon included;
* ``project, full hold``: the same with ``settle_checks: 0``, every passing direction simulated
  for the whole hold (the reference the verdicts are compared with);
* ``project, palm, full hold``: that with ``hand_root: palm`` (wrist held, forearm out of the
  scene);
* ``peer loop``: a re-implementation of the loop structure of DexGraspBench's ``fcMocapEval``
  (read, not copied; github.com/JYChen18/DexGraspBench src/task/eval_func/{base,fc_mocap}.py):
  the hand rooted at the palm (its Shadow MJCF has no forearm), a pregrasp penetration check,
  then for each of the six directions in turn: reset to the pregrasp, re-simulate the closing
  pregrasp -> grasp -> squeeze, apply the force and step 10 x 50 steps, checking the object's
  pose after each 50 and stopping that direction at the first failure; the first failing
  direction ends the grasp. Same physics constants (the protocol, `EvalConfig`), same scene
  (palm-rooted), contact metrics at the grasp pose as its ``_eval_pene_and_contact`` does; no
  epsilon (its q1 metric is a separate pass).

Each mode runs over all grasps ``--repeats`` times; the figure is the median over the runs of
the mean CPU seconds per grasp. Verdict agreement (success or not) is reported against the
project's full hold.

    python -m benchmarks.bench_eval --grasps A.parquet [B.parquet ...] [--limit 64] [--repeats 3] [--agreement]

``--agreement``: also evaluate every row of the tables (no limit, not timed) under both rootings
and report how often the verdicts agree (the measured set behind ``hand_root: palm``).
``--early-agreement [TABLE ...]``: every row of those tables (default: the ``--grasps`` ones), any hand and task (no limit, not timed), under
the default early pass and under the full hold: how often the verdicts agree, per hand, and the
simulated steps of each (the measured set behind the early pass being the default).

Without ``--grasps`` it uses constructed grasps (a box against the Shadow palm, tests/eval/grasps.py).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
import torch

from benchmarks.common import hand_notes, machine_description
from datagen.eval import EvalConfig, Evaluator
from datagen.eval.config import DIRECTIONS
from datagen.eval.hold import close_hand, initial_state
from datagen.eval.metrics import static_metrics
from datagen.hands import load_hand
from datagen.rotation import quat_angle_np

OUT = Path(__file__).parent / "results" / "eval.md"


def peer_loop(ev: Evaluator, pieces, poses) -> bool:
    """One grasp under the peer's loop structure (module docstring); ``ev`` palm-rooted."""
    cfg = ev.cfg
    scene, datas = ev.scene(pieces)
    static = datas[-1]
    pre = static_metrics(scene, static, poses[0], touch_distance=cfg.touch_distance_m,
                         contact_distance=cfg.contact_distance_m)
    if max(pre.penetration, pre.self_penetration) > cfg.max_pregrasp_penetration_m:
        return False
    static_metrics(scene, static, poses[1], touch_distance=cfg.touch_distance_m,
                   contact_distance=cfg.contact_distance_m)  # its penetration / contact metrics
    d, m, b = datas[0], scene.model, scene.object_body
    f = cfg.force_per_kg * scene.object_mass
    for direction in DIRECTIONS:
        initial_state(scene, d, poses[0])
        pos0, quat0 = d.xpos[b].copy(), d.xquat[b].copy()
        close_hand(scene, d, poses, cfg)
        d.xfrc_applied[b] = [*(f * np.asarray(direction)), 0.0, 0.0, 0.0]
        ok = True
        for _ in range(cfg.hold_steps // cfg.check_every):
            mujoco.mj_step(m, d, nstep=cfg.check_every)
            t = float(np.linalg.norm(d.xpos[b] - pos0))
            r = float(np.degrees(quat_angle_np(d.xquat[b], quat0)))
            ok = t < cfg.max_translation_m and r < cfg.max_rotation_deg
            if not ok:
                break
        d.xfrc_applied[b] = 0.0
        if not ok:
            return False
    return True


def load_grasps(paths: list[str], limit: int | None, tmp: Path) -> list[tuple[str, object, np.ndarray]]:
    """(object id, pieces, poses (3, 7 + J)) of the tables' rows (spread evenly if ``limit``)."""
    if not paths:
        from tests.eval.grasps import box_grasp

        ev = Evaluator(load_hand("shadow"))
        out = []
        for hy in (0.015, 0.02):
            for drop in (0.0, 0.015, 0.03):
                pieces, poses = box_grasp(ev, (0.03, hy, 0.03), drop, tmp)
                out.append((f"box {2 * hy * 100:.0f} cm, drop {drop * 100:.1f} cm", pieces, poses))
        return out
    from datagen.eval.table import read_grasps, row_pieces, row_poses, table_base

    rows = []
    for p in paths:
        base = table_base(p)
        for row in read_grasps(Path(p)).to_pylist():
            if row["hand"] != "shadow" or row["task"] != "force_closure":
                continue
            rows.append((row["object_id"], row_pieces(row, base), row_poses(row)))
    if limit and len(rows) > limit:
        rows = [rows[i] for i in np.linspace(0, len(rows) - 1, limit).round().astype(int)]
    return rows


def run_mode(fn, grasps, repeats: int) -> tuple[list[float], list[bool]]:
    """Per-run mean CPU seconds per grasp (``repeats`` runs, after a warm-up pass that builds the
    scenes) and the verdicts."""
    verdicts = [bool(fn(p, q)) for _, p, q in grasps]
    runs = []
    for _ in range(repeats):
        c0 = time.process_time()
        for _, p, q in grasps:
            fn(p, q)
        runs.append((time.process_time() - c0) / len(grasps))
    return runs, verdicts


def early_agreement(paths: list[str]) -> list[tuple[str, bool, bool, int, int]]:
    """(hand, early-pass verdict, full-hold verdict, steps early, steps full) of every row of the
    tables (any hand and task; rows keep their own task and task wrench)."""
    from datagen.eval.table import read_grasps, row_pieces, row_poses, table_base

    evaluators: dict[str, tuple[Evaluator, Evaluator]] = {}
    out = []
    for p in paths:
        base = table_base(p)
        for row in read_grasps(Path(p)).to_pylist():
            h = str(row["hand"])
            if h not in evaluators:
                hand = load_hand(h)
                evaluators[h] = (Evaluator(hand, EvalConfig()), Evaluator(hand, EvalConfig(settle_checks=0)))
            pieces, poses = row_pieces(row, base), row_poses(row)
            a, b = (ev.evaluate(pieces, poses, str(row["task"]), w_t=row.get("w_t")) for ev in evaluators[h])
            out.append((h, bool(a.success), bool(b.success), a.sim_steps, b.sim_steps))
    for pair in evaluators.values():
        for ev in pair:
            ev.close()
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--grasps", nargs="*", default=[], help="grasp tables (Shadow, force_closure rows)")
    ap.add_argument("--limit", type=int, default=64, help="at most this many rows, spread over the tables")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--agreement", action="store_true", help="verdicts of every row under both rootings")
    ap.add_argument("--early-agreement", nargs="*", default=None, metavar="TABLE",
                    help="verdicts of every row (any hand, task) of these tables (none named: the --grasps "
                         "tables) under the early pass and the full hold")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    t_start = time.perf_counter()
    machine = machine_description()
    hand = load_hand("shadow")
    with tempfile.TemporaryDirectory(prefix="bench-eval-") as tmp:
        grasps = load_grasps(args.grasps, args.limit, Path(tmp))
        default = Evaluator(hand, EvalConfig())
        spec = Evaluator(hand, EvalConfig(hand_root="spec", settle_checks=0))
        project = Evaluator(hand, EvalConfig(hand_root="palm", settle_checks=0))
        peer = Evaluator(hand, EvalConfig(hand_root="palm", settle_checks=0))
        modes = {"project (default: hand_root spec, early pass)": lambda p, q: default.evaluate(p, q).success,
                 "project, full hold (settle_checks 0)": lambda p, q: spec.evaluate(p, q).success,
                 "project, hand_root palm, full hold": lambda p, q: project.evaluate(p, q).success,
                 "peer loop (palm-rooted, closing per direction)": lambda p, q: peer_loop(peer, p, q)}
        results = {k: run_mode(fn, grasps, args.repeats) for k, fn in modes.items()}
        reasons = [default.evaluate(p, q).reason for _, p, q in grasps]
        agreement = []
        if args.agreement and args.grasps:
            for oid, p, q in load_grasps(args.grasps, None, Path(tmp)):
                a, b = project.evaluate(p, q), spec.evaluate(p, q)
                agreement.append((oid, a.success, b.success, a.reason, b.reason, a.sim_steps > 0))
        early_tables = (args.early_agreement or args.grasps) if args.early_agreement is not None else []
        early = early_agreement(early_tables) if early_tables else []
    ref = results["project, full hold (settle_checks 0)"][1]
    peer_cpu = statistics.median(results["peer loop (palm-rooted, closing per direction)"][0])
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent).stdout.strip()
    except OSError:
        commit = "?"
    from collections import Counter

    objects = sorted({g[0] for g in grasps})
    lines = ["# Evaluation cost: the project's evaluator against the peer's loop (same grasps)", "",
             f"Machine: {machine}; mujoco {mujoco.__version__}; commit {commit}.", "",
             "Generated by `make bench-eval` (benchmarks/bench_eval.py; the modes are described in its docstring). "
             f"{len(grasps)} Shadow grasps on {len(objects)} objects"
             + (f" from {', '.join(Path(p).name for p in args.grasps)}" if args.grasps else " (constructed box grasps)")
             + f"; project verdicts: {', '.join(f'{k} {v}' for k, v in Counter(reasons).most_common())}. "
             f"CPU seconds per grasp (process time, one thread): median over {args.repeats} runs of the mean "
             "over the grasps (a warm-up pass builds the scenes first). The machine is shared (2 cores, other "
             "jobs running): CPU time, not wall time, is the figure.", "",
             "| mode | CPU s per grasp (median) | runs | x peer | successes | success verdict agrees with the full hold |",
             "|---|---|---|---|---|---|"]
    for k, (runs, verdicts) in results.items():
        agree = sum(a == b for a, b in zip(verdicts, ref))
        lines.append(f"| {k} | {statistics.median(runs):.3f} | {', '.join(f'{r:.3f}' for r in runs)} | "
                     f"{statistics.median(runs) / peer_cpu:.2f} | {sum(verdicts)}/{len(verdicts)} | "
                     f"{agree}/{len(verdicts)} ({100 * agree / len(verdicts):.1f}%) |")
    if agreement:
        n = len(agreement)
        same = sum(a == b for _, a, b, _, _, _ in agreement)
        same_r = sum(ra == rb for _, _, _, ra, rb, _ in agreement)
        sim = [x for x in agreement if x[5]]
        lines += ["", f"## Rooting: hand_root palm (default) against spec, every row ({n} grasps, "
                      f"{len({x[0] for x in agreement})} objects, {len(sim)} simulated)", "",
                  f"- success verdict agrees on {same}/{n} ({100 * same / n:.1f}%); among simulated grasps "
                  f"{sum(a == b for _, a, b, _, _, _ in sim)}/{len(sim)}",
                  f"- reason code agrees on {same_r}/{n} ({100 * same_r / n:.1f}%)",
                  f"- successes: palm {sum(x[1] for x in agreement)}, spec {sum(x[2] for x in agreement)}"]
    if early:
        lines += ["", "## Early pass (default) against the full hold, every row", "",
                  f"Tables: {', '.join(early_tables)}. Steps: MuJoCo steps simulated per row (closing and holds).", "",
                  "| hand | rows | simulated | successes (full hold) | verdict agrees | false passes | false fails | "
                  "steps, early / full |", "|---|---|---|---|---|---|---|---|"]
        for h in sorted({x[0] for x in early}):
            xs = [x for x in early if x[0] == h]
            sim = [x for x in xs if x[4] > 0]
            lines.append(f"| {h} | {len(xs)} | {len(sim)} | {sum(x[2] for x in xs)} | "
                         f"{sum(x[1] == x[2] for x in xs)} | {sum(x[1] and not x[2] for x in xs)} | "
                         f"{sum(x[2] and not x[1] for x in xs)} | {sum(x[3] for x in xs) / max(1, sum(x[4] for x in xs)):.3f} |")
    lines += ["", f"Objects: {', '.join(objects)}.", "",
              f"Total benchmark time: {time.perf_counter() - t_start:.0f} s."]
    # keep the hand-written notes, and an earlier run's rooting section when this run has none
    kept = hand_notes(args.out) if args.agreement else (hand_notes(args.out, "## Rooting") or hand_notes(args.out))
    lines += [""] + kept if kept else []
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
