"""`datagen synth` end to end on real meshes, by seeds per grasp -> benchmarks/results/synth_cli.md.

The command a user types, ``datagen synth --object MESH --num 100 --iters 500 [--seeds S]``
(Shadow, force closure, 0.08 m), timed as a subprocess from start to exit on a warm objects
cache (one untimed run per mesh first processes it and builds its SDF grid), then its grasps
through ``datagen eval --workers 2`` (the six-direction test). The same seed gives the same
grasps, so each setting is evaluated once; the wall time is the median of ``--runs`` runs,
settings alternating. Besides the wall time, the figure that counts for a dataset: validated
grasps per second of synthesis, and per second of synthesis plus evaluation.

    python -m benchmarks.bench_synth_cli [--seeds 16,8,4] [--runs 2] [--objects mug,duck,bunny]

The meshes are pybullet_data's (``make real-objects``). 16 seeds is the default
(the ``dataset`` preset, `datagen.pipeline.PRESETS`): what each setting buys in success rate is the
trade-off against the issue's 15 s.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import hand_notes, machine_description, write_report
from workers.job import code_version

RESULTS = Path(__file__).parent / "results" / "synth_cli.md"
MESHES = {"mug": "objects/mug.obj", "duck": "duck.obj", "bunny": "bunny.obj"}
TARGET_S = 15.0


def _mesh(name: str) -> Path:
    try:
        import pybullet_data
    except ImportError:
        raise SystemExit("pybullet_data is not installed: run `make real-objects`") from None
    path = Path(pybullet_data.getDataPath()) / MESHES[name]
    if not path.is_file():
        raise SystemExit(f"{path}: not found in pybullet_data")
    return path


def _default_threads() -> int:
    """torch's default intra-op threads here, which the `datagen synth` subprocess also uses."""
    import torch

    return torch.get_num_threads()


def _cli(*args: str, check: bool = True) -> tuple[float, str]:
    """(wall s, the last "wrote ..." line) of ``python -m datagen.cli ARGS``; raises on failure if ``check``."""
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "datagen.cli", *args], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if check and p.returncode != 0:
        raise SystemExit(f"datagen {' '.join(args)} failed ({p.returncode}):\n{p.stderr[-2000:]}")
    lines = [x for x in (p.stdout + "\n" + p.stderr).replace("\r", "\n").splitlines() if x.startswith("wrote ")]
    return wall, lines[-1] if lines else ""


def _synth(mesh: Path, seeds: int, out: Path, num: int, iters: int) -> float:
    return _cli("synth", "--object", str(mesh), "--num", str(num), "--iters", str(iters), "--seeds", str(seeds),
                "--out", str(out))[0]


def _successes(table: Path, out: Path) -> tuple[int, float]:
    """(successful grasps, eval wall s) of ``datagen eval --workers 2``."""
    wall, last = _cli("eval", str(table), "--out", str(out), "--workers", "2")
    m = re.search(r"(\d+) successful", last)
    if m is None:
        raise SystemExit(f"datagen eval printed no success count: {last!r}")
    return int(m.group(1)), wall


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="16,8,4", help="comma-separated seeds per grasp (the first: the default)")
    ap.add_argument("--objects", default="mug,duck,bunny", help=f"pybullet_data meshes, of {', '.join(MESHES)}")
    ap.add_argument("--runs", type=int, default=2, help="timed runs per setting and mesh, settings alternating")
    ap.add_argument("--num", type=int, default=100)
    ap.add_argument("--iters", type=int, default=500)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    names = [n for n in args.objects.split(",") if n.strip()]
    meshes = {n: _mesh(n) for n in names}
    header = machine_description()
    walls = {(n, s): [] for n in names for s in seeds}
    ok, eval_s = {}, {}
    with tempfile.TemporaryDirectory(prefix="bench_synth_cli_") as tmp:
        tmp = Path(tmp)
        for n, mesh in meshes.items():  # the warm cache: processed object and SDF grid (a 1-iteration
            _cli("synth", "--object", str(mesh), "--num", "1", "--iters", "1", "--seeds", "1",  # grasp may be unusable)
                 "--out", str(tmp / "warm.parquet"), check=False)
        for r in range(args.runs):
            for s in (seeds if r % 2 == 0 else seeds[::-1]):
                for n, mesh in meshes.items():
                    table = tmp / f"{n}_{s}.parquet"
                    walls[n, s].append(_synth(mesh, s, table, args.num, args.iters))
                    print(f"run {r + 1}: {n}, {s} seeds: {walls[n, s][-1]:.1f} s", flush=True)
                    if (n, s) not in ok:
                        ok[n, s], eval_s[n, s] = _successes(table, tmp / f"{n}_{s}_eval.parquet")
                        print(f"  {ok[n, s]} of {args.num} hold ({eval_s[n, s]:.1f} s eval)", flush=True)
    load = os.getloadavg()
    lines = ["# `datagen synth` end to end, by seeds per grasp (`make bench-synth-cli`)", "",
             f"Commit {code_version()}.", "",
             f"Machine: {header}; load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}.", "",
             f"Command: `datagen synth --object MESH --num {args.num} --iters {args.iters} --seeds S` (Shadow, force "
             f"closure, 0.08 m, torch's default {_default_threads()} threads), a subprocess timed from start to exit, warm objects cache; wall = "
             f"median of {args.runs} runs, settings alternating. Then `datagen eval --workers 2` (six-direction "
             "test) once per setting: the grasps are the same on every run. Validated / s = grasps that hold per "
             "second of synthesis wall (and of synthesis + evaluation wall).", "",
             "| seeds per grasp | " + " | ".join(f"{n} wall (s)" for n in names) + " | median wall (s) | "
             f"<= {TARGET_S:.0f} s | hold % | validated / s synth | validated / s synth + eval |",
             "|---" * (len(names) + 6) + "|"]
    summary = {}
    for s in seeds:
        med = {n: statistics.median(walls[n, s]) for n in names}
        wall = statistics.median(med.values())
        held = sum(ok[n, s] for n in names)
        synth_total = sum(med.values())
        both = synth_total + sum(eval_s[n, s] for n in names)
        summary[s] = (wall, 100 * held / (args.num * len(names)))
        label = f"{s} (default)" if s == seeds[0] else str(s)
        lines.append(f"| {label} | " + " | ".join(f"{med[n]:.1f}" for n in names) + f" | {wall:.1f} | "
                     f"{'yes' if wall <= TARGET_S else 'no'} | {summary[s][1]:.1f} | {held / synth_total:.2f} | "
                     f"{held / both:.2f} |")
    lines += ["", "Per mesh, grasps that hold of " + str(args.num) + ": " + "; ".join(
        f"{n} " + ", ".join(f"{ok[n, s]} ({s} seeds)" for s in seeds) for n in names) + ".", ""]
    verdict = "synth-cli: " + " ".join(f"seeds{s}={summary[s][0]:.1f}s/{summary[s][1]:.1f}%" for s in seeds)
    lines += hand_notes(args.out) + ["```", verdict, "```", ""]
    write_report(args.out, lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
