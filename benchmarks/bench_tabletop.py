"""Tabletop grasps on real objects: the default force-closure job with ``--scene tabletop``.

Runs the product itself, ``datagen run`` (Ray, the default job, nothing relaxed) with the object
resting on a table in its most probable stable pose(s) and the lift test (DexGraspBench's
``tabletop`` setting: 1 N down on the object, pregrasp -> grasp -> squeeze, lift 10 cm, pass
within 5 cm and 15 deg; datagen/eval/lift.py), on a real-object manifest at the job's default
scales, per hand. Reports success, the reasons of the failures, and how many successes have the
hand deeper than 1 mm in the table at the grasp (the lift test rejects a hand deeper than
``max_table_penetration_m`` as hand_in_table before simulating, so this is 0 by construction; the
count of all rows so rejected is the ``hand_in_table`` column).

Usage: ``python -m benchmarks.bench_tabletop --hands shadow,allegro --objects 12 --grasps 2
--work DIR [--manifest manifests/real_holdout.jsonl] [--out benchmarks/results/tabletop.md]``.
Prints the table; ``--out`` writes it (with its command, code version and machine) as the page's
latest table, the page's hand-written text below ``## Notes`` kept.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from benchmarks.bench_quality import with_scales
from benchmarks.common import machine_description
from datagen.io import read_job
from workers.job import JobConfig, code_version

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["object_id", "object_scale_m", "stable_pose", "success", "reason", "table_penetration_m", "penetration_m",
           "grasp_type"]
REASONS = ("object_left_on_table", "object_dropped", "object_slipped", "hand_in_table", "penetration", "no_contact",
           "unstable")


def run_job(hand: str, out: Path, manifest: Path, objects: int, grasps: int, stable_poses: int) -> None:
    cmd = [sys.executable, "-m", "datagen.cli", "run", "--out", str(out), "--manifest", str(manifest),
           "--objects", str(objects), "--hand", hand, "--tasks", "force_closure", "--grasps", str(grasps),
           "--scene", "tabletop", "--stable-poses", str(stable_poses), "--num-cpus", "1", "--no-progress"]
    subprocess.run(cmd, check=True, cwd=ROOT)


def hand_rows(hand: str, rows: dict) -> list[str]:
    ok = np.asarray(rows["success"], dtype=bool)
    scales = np.round(np.asarray(rows["object_scale_m"], dtype=float), 4)
    table = np.asarray(rows["table_penetration_m"], dtype=float)
    out = []
    for name, sel in [("all", np.ones_like(ok))] + [(f"{s:g} m", scales == s) for s in sorted(set(scales.tolist()))]:
        why = Counter(np.asarray(rows["reason"])[sel & ~ok].tolist())
        out.append(f"| {hand} | {name} | {int(sel.sum())} | {100 * ok[sel].mean():.1f} | "
                   f"{int((ok & sel & (table > 0.001)).sum())} | "
                   + " | ".join(str(why.get(r, 0)) for r in REASONS) + " |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hands", default="shadow,shadow_e3m5,allegro,leap")
    ap.add_argument("--manifest", default=str(ROOT / "manifests" / "real_dev.jsonl"))
    ap.add_argument("--objects", type=int, default=12)
    ap.add_argument("--grasps", type=int, default=2)
    ap.add_argument("--stable-poses", type=int, default=1)
    ap.add_argument("--work", required=True, help="folder of the jobs (rerun: finished jobs are read back)")
    ap.add_argument("--out", default=None, help="write the results page here")
    args = ap.parse_args(argv)
    work = Path(args.work)
    manifest = with_scales(Path(args.manifest), tuple(float(s) for s in JobConfig().scales), work)
    lines = ["| hand | scale | n | lift success % | successes with the hand > 1 mm in the table | "
             + " | ".join(REASONS) + " |", "|---|---|---|---|---|" + "---|" * len(REASONS)]
    for hand in args.hands.split(","):
        job = work / f"{Path(args.manifest).stem}-{hand}"
        run_job(hand, job, manifest, args.objects, args.grasps, args.stable_poses)
        lines += hand_rows(hand, read_job(job, columns=COLUMNS).to_pydict())
    print("\n".join(lines))
    if args.out:
        head = ["# Tabletop grasps on real objects (`--scene tabletop`, the lift test)", "",
                f"Code {code_version()}; machine: {machine_description()}.", "",
                "    python -m benchmarks.bench_tabletop " + " ".join(argv if argv is not None else sys.argv[1:]), "",
                f"Objects: the first {args.objects} of `{Path(args.manifest).relative_to(ROOT)}` at the job's default "
                f"scales {', '.join(f'{s:g}' for s in JobConfig().scales)} m, each in its {args.stable_poses} most "
                f"probable stable pose(s), {args.grasps} grasps per object, scale and pose; the default job "
                "otherwise (the dataset preset). Failures by reason code.", ""]
        page = Path(args.out)
        notes = page.read_text().split("## Notes", 1)[1] if page.is_file() and "## Notes" in page.read_text() else "\n"
        page.write_text("\n".join(head + lines) + "\n\n## Notes" + notes)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
