"""Tabletop verdicts against DexGraspBench's own evaluator in its ``setting=tabletop``.

For each ``HAND=JOB`` (a ``datagen run --scene tabletop`` job, e.g. from `benchmarks.bench_tabletop`):
``datagen export JOB --format dexgraspbench`` (tabletop rows in the table frame: the peer's floor at
z = 0 under the object at its stable pose), the peer's evaluator on those files, its code unchanged
(``python src/main.py hand=H task=eval exp_name=datagen setting=tabletop``, in its own environment),
then the agreement of the job's own ``success`` (this project's lift test) with the peer's
``succ_flag``, grasp by grasp, and the disagreements.

    python -m benchmarks.bench_tabletop_interop --job leap=J1 --job allegro=J2 --job shadow_e3m5=J3 \\
        --peer DGB --peer-python DGB_VENV/bin/python --work WORK [--out benchmarks/results/tabletop.md]

``--out`` adds the table under the page's ``## Interop`` heading (replacing an older one).
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

import mujoco

from benchmarks.bench_interop import PEER_NAME, _pct, export, peer_verdicts, run_peer
from datagen.io import read_job

ROOT = Path(__file__).resolve().parents[1]


def compare(hand: str, job: Path, work: Path, peer: Path, python: str, workers: int) -> tuple[list, list]:
    """``(row, disagreements)`` of one hand: grasps, the peer's successes, ours, agreement."""
    save_root = work / "peer_out"
    files = export(job, save_root / f"datagen_{PEER_NAME[hand]}")
    wall = run_peer(peer, python, PEER_NAME[hand], save_root, workers, setting="tabletop")
    theirs = peer_verdicts(save_root, PEER_NAME[hand])
    ours = {r["grasp_id"]: r for r in read_job(job, columns=["grasp_id", "object_id", "object_scale_m", "success",
                                                             "reason", "dir_translation_m", "dir_rotation_deg"]).to_pylist()}
    pairs = [(ours[files[f]], theirs[f]) for f in files if f in theirs]
    agree = sum(o["success"] == t["succ"] for o, t in pairs)
    row = [hand, len(pairs), sum(t["succ"] for _, t in pairs), sum(o["success"] for o, _ in pairs), agree, wall]
    return row, [(hand, o, t) for o, t in pairs if o["success"] != t["succ"]]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--job", action="append", required=True, metavar="HAND=JOB")
    ap.add_argument("--peer", required=True)
    ap.add_argument("--peer-python", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    work, peer = Path(args.work).resolve(), Path(args.peer).resolve()
    rows, details = [], []
    for item in args.job:
        hand, _, job = item.partition("=")
        row, dis = compare(hand, Path(job).resolve(), work, peer, args.peer_python, args.workers)
        rows.append(row)
        details += dis
    peer_commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=peer).stdout.strip()
    peer_mj = subprocess.run([args.peer_python, "-c", "import mujoco; print(mujoco.__version__)"],
                             capture_output=True, text=True).stdout.strip()
    lines = ["## Interop: the lift against DexGraspBench's `setting=tabletop`", "",
             f"DexGraspBench {peer_commit} (its code unchanged) on mujoco {peer_mj}; this project on mujoco "
             f"{mujoco.__version__}. The same grasps: the jobs' rows exported (`datagen export --format "
             "dexgraspbench`), its verdict `succ_flag` against the rows' own `success`.", "",
             "    python -m benchmarks.bench_tabletop_interop " + " ".join(f"--job {j}" for j in args.job)
             + " --peer DGB --peer-python DGB_VENV/bin/python --work WORK", "",
             "| hand | grasps | peer successes | our successes | verdicts agree | peer wall s |", "|---|---|---|---|---|---|"]
    lines += [f"| {h} | {n} | {ps} | {os_} | {_pct(a, n)} | {w:.0f} |" for h, n, ps, os_, a, w in rows]
    if details:
        lines += ["", "Disagreements:", "", "| hand | object | scale m | peer succ | peer delta mm / deg | our reason | "
                  "our mm / deg |", "|---|---|---|---|---|---|---|"]
        for h, o, t in details:
            lines.append(f"| {h} | {o['object_id']} | {o['object_scale_m']:.2f} | {t['succ']} | "
                         f"{t['delta_pos'] * 1000:.1f} / {t['delta_angle']:.1f} | {o['reason']} | "
                         f"{(o['dir_translation_m'][0] or float('nan')) * 1000:.1f} / {o['dir_rotation_deg'][0] or float('nan'):.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        page = Path(args.out)
        old = page.read_text() if page.is_file() else ""
        head, _, rest = old.partition("## Interop")
        notes = rest[rest.index("## Notes"):] if "## Notes" in rest else (old[old.index("## Notes"):] if "## Notes" in head else "")
        head = head.split("## Notes")[0].rstrip() + "\n\n"
        page.write_text(head + text + ("\n" + notes if notes else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
