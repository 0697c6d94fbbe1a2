"""Evaluation cost against DexGraspBench's own evaluator: the same grasps, the same machine, one run
-> a section of benchmarks/results/eval.md.

    python -m benchmarks.eval_peer_cost --hand leap=JOB=EXPORT --hand allegro=JOB=EXPORT \\
        --peer DGB --peer-python DGB_VENV/bin/python --work WORK [--grasps 60]

``JOB``: a job directory of that hand (its shards' rows, read as Parquet whatever their schema
version); ``EXPORT``: its `datagen export --format dexgraspbench` folder (``.../datagen_<peer hand>``,
with ``graspdata/``). Per hand, in this order:

1. ``--grasps`` of the exported files (every k-th, sorted by path, so every object and scale is in)
   are copied to ``WORK/<hand>/datagen_<peer hand>/graspdata``;
2. this project's evaluator (default `EvalConfig`: the hand's protocol, the early pass) on the
   same rows in this process, one torch thread: CPU seconds (process time) over the grasps,
   scenes built on the way included, the imports before the clock (a fixed cost, as the peer's
   is below);
3. the peer, its code unchanged (``python src/main.py hand=<h> task=eval exp_name=datagen
   save_root=WORK/<hand> n_worker=1``): CPU seconds of the process and its children
   (``RUSAGE_CHILDREN``); then the same command again, every file now evaluated (it skips them):
   its fixed cost (interpreter, imports, hydra), subtracted, so the peer's figure is per grasp;
4. verdict agreement: our ``success`` against the peer's ``succ_flag``, grasp by grasp.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from benchmarks.common import machine_description, replace_section

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "eval.md"
HEADING = "## Against DexGraspBench's own evaluator: CPU per grasp and verdicts (real meshes)"
PEER_NAME = {"leap": "leap", "allegro": "allegro", "shadow_e3m5": "shadow"}


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _subset(export: Path, dest: Path, n: int) -> dict[str, str]:
    """Copy ``n`` of ``export/graspdata``'s files to ``dest/graspdata``; {relative path: grasp_id}."""
    files = sorted((export / "graspdata").rglob("*.npy"))
    step = max(1, len(files) // n)
    picked = files[::step][:n]
    out = {}
    for f in picked:
        rel = f.relative_to(export / "graspdata")
        (dest / "graspdata" / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(f, dest / "graspdata" / rel)
        out[str(rel)] = str(np.load(f, allow_pickle=True).item()["grasp_id"])
    return out


def ours(job: Path, hand_name: str, ids: set[str]) -> tuple[dict[str, dict], float]:
    """{grasp_id: {succ, reason}} of the default evaluator and its CPU seconds over those rows."""
    import torch

    from datagen.eval import EvalConfig, Evaluator
    from datagen.eval.table import row_pieces, row_poses
    from datagen.hands import load_hand
    from datagen.objects import load_processed  # noqa: F401 (row_pieces' imports: trimesh, ~1 s, once)

    torch.set_num_threads(1)
    rows = [r for f in sorted((job / "shards").glob("part-*.parquet")) for r in pq.read_table(f).to_pylist()
            if r["grasp_id"] in ids]
    out = {}
    with Evaluator(load_hand(hand_name), EvalConfig()) as ev:
        t0 = time.process_time()
        for r in rows:
            res = ev.evaluate(row_pieces(r, job), row_poses(r), str(r["task"]))
            out[r["grasp_id"]] = {"succ": bool(res.success), "reason": res.reason}
        cpu = time.process_time() - t0
    return out, cpu


def peer(checkout: Path, python: str, hand: str, save_root: Path) -> float:
    """CPU seconds of one run of the peer's evaluation over ``save_root/datagen_<hand>``."""
    c0 = _children_cpu()
    subprocess.run([python, "src/main.py", f"hand={hand}", "task=eval", "exp_name=datagen",
                    f"save_root={save_root}", "n_worker=1"], check=True, cwd=checkout, capture_output=True)
    return _children_cpu() - c0


def peer_verdicts(save_root: Path, hand: str) -> dict[str, bool]:
    ev = save_root / f"datagen_{hand}" / "evaluation"
    return {str(p.relative_to(ev)): bool(np.load(p, allow_pickle=True).item()["succ_flag"])
            for p in sorted(ev.rglob("*.npy"))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hand", action="append", required=True, metavar="HAND=JOB=EXPORT")
    ap.add_argument("--peer", required=True)
    ap.add_argument("--peer-python", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--grasps", type=int, default=60)
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    work, checkout = Path(args.work).resolve(), Path(args.peer).resolve()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT).stdout.strip()
    peer_commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=checkout).stdout.strip()
    peer_mj = subprocess.run([args.peer_python, "-c", "import mujoco; print(mujoco.__version__)"], capture_output=True,
                             text=True).stdout.strip()
    machine = machine_description()
    table = []
    for item in args.hand:
        hand, job, export = item.split("=")
        ph = PEER_NAME[hand]
        save_root = work / hand
        shutil.rmtree(save_root, ignore_errors=True)
        files = _subset(Path(export), save_root / f"datagen_{ph}", args.grasps)
        mine, cpu_ours = ours(Path(job), hand, set(files.values()))
        cpu_peer = peer(checkout, args.peer_python, ph, save_root)
        cpu_fixed = peer(checkout, args.peer_python, ph, save_root)  # every file done: its fixed cost
        theirs = peer_verdicts(save_root, ph)
        if len(theirs) < len(files):  # e.g. its hand's meshes missing: it logs each file and goes on
            raise SystemExit(f"{hand}: the peer evaluated {len(theirs)} of {len(files)} grasps; its log: "
                             f"{save_root / f'datagen_{ph}' / 'log'}")
        pairs = [(mine[g], theirs[k]) for k, g in files.items() if k in theirs and g in mine]
        agree = sum(a["succ"] == b for a, b in pairs)
        n = len(pairs)
        per_peer = (cpu_peer - cpu_fixed) / max(n, 1)
        per_ours = cpu_ours / max(len(mine), 1)
        table.append((hand, n, sum(a["succ"] for a, _ in pairs), sum(b for _, b in pairs), agree, per_ours, per_peer,
                      cpu_peer, cpu_fixed))
        print(f"{hand}: {n} grasps, ours {per_ours:.3f} s/grasp, peer {per_peer:.3f} s/grasp "
              f"(run {cpu_peer:.1f} s, fixed {cpu_fixed:.1f} s), agree {agree}/{n}", flush=True)
    import os

    load = os.getloadavg()
    lines = [HEADING, "",
             f"Commit {commit}; DexGraspBench {peer_commit} (its code unchanged, its own environment, mujoco {peer_mj}). "
             f"Machine: {machine}; load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}. Command: "
             f"`python -m benchmarks.eval_peer_cost {' '.join('--hand ' + h.split('=')[0] + '=JOB=EXPORT' for h in args.hand)} "
             f"--peer DGB --peer-python DGB_VENV/bin/python --work WORK --grasps {args.grasps}` "
             "(benchmarks/eval_peer_cost.py: the steps are in its docstring). Same grasps, same machine, one run: "
             "ours (default EvalConfig, one thread, scenes included) first, then the peer (n_worker 1) and its "
             "fixed cost (a second run that skips every file), subtracted.", "",
             "| hand | grasps | our successes | peer successes | verdicts equal | our CPU s / grasp | peer CPU s / grasp "
             "| ratio (ours / peer) |", "|---|---|---|---|---|---|---|---|"]
    for hand, n, so, sp, agree, po, pp, cp, cf in table:
        lines.append(f"| {hand} | {n} | {so} | {sp} | {agree}/{n} ({100 * agree / max(n, 1):.1f}%) | {po:.3f} | "
                     f"{pp:.3f} | **{po / pp:.2f}x** |")
    lines += ["", "Peer CPU per run (all grasps / fixed cost of a run that evaluates none): " + "; ".join(
        f"{t[0]} {t[7]:.1f} / {t[8]:.1f} s" for t in table) + ".", ""]
    replace_section(args.out, HEADING, lines, first=True)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
