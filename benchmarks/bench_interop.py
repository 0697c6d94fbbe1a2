"""Side by side with DexGraspBench's own evaluator: the same grasps, its verdicts and ours -> interop.md.

For each job (one hand's default force-closure job on real meshes, ``datagen run``):

1. ``datagen export JOB --format dexgraspbench`` into ``WORK/peer_out/datagen_<peer hand>``;
2. DexGraspBench's evaluator on those files, its code unchanged, in its own environment
   (``--peer`` a checkout at 1e7a5a6 with its Menagerie submodule, ``--peer-python`` a Python with
   its pinned mujoco 3.3.2): ``python src/main.py hand=<h> task=eval exp_name=datagen
   save_root=WORK/peer_out n_worker=N`` (setting ``fc``, the six-direction test; files it
   evaluated before are skipped, as it does);
3. this project's evaluator on the job's rows under each variant: the default (``protocol:
   dexgraspbench``, early pass), the full hold (``settle_checks: 0``) and ``protocol: uniform``;
4. agreement of each variant's success verdict with the peer's ``succ_flag``, per hand, and the
   early pass against the full hold (false passes: the early pass passes, the full hold fails).

Jobs given with ``--early-only`` (a hand the peer does not have, e.g. the gymnasium Shadow) get
step 3 and the early-pass comparison only. Our verdicts are cached under ``WORK`` (per hand and
variant) so a rerun redoes only what is missing.

    python -m benchmarks.bench_interop --job leap=J1 --job allegro=J2 --job shadow_e3m5=J3 \\
        --early-only shadow=J4 --peer DGB --peer-python DGB_VENV/bin/python --work WORK
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

from benchmarks.common import hand_notes, machine_description, write_report

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "interop.md"
PEER_NAME = {"leap": "leap", "allegro": "allegro", "shadow_e3m5": "shadow"}
VARIANTS = {"default": {}, "full hold": {"settle_checks": 0}, "uniform": {"protocol": "uniform"}}


def export(job: Path, out: Path) -> dict[str, str]:
    """Export ``job`` to DexGraspBench files under ``out``; {file path relative to graspdata: grasp_id}."""
    gd = out / "graspdata"
    if not gd.is_dir():
        subprocess.run([sys.executable, "-m", "datagen.cli", "export", str(job), "--format", "dexgraspbench",
                        "--out", str(out)], check=True, cwd=ROOT)
    return {str(p.relative_to(gd)): str(np.load(p, allow_pickle=True).item()["grasp_id"])
            for p in sorted(gd.rglob("*.npy"))}


def run_peer(peer: Path, python: str, hand: str, save_root: Path, workers: int, setting: str = "fc") -> float:
    """DexGraspBench's evaluation of ``save_root/datagen_<hand>/graspdata`` in its ``setting`` (``fc``
    six directions, ``tabletop`` the lift); wall seconds."""
    t0 = time.perf_counter()
    subprocess.run([python, "src/main.py", f"hand={hand}", "task=eval", "exp_name=datagen",
                    f"save_root={save_root}", f"n_worker={workers}", f"setting={setting}"], check=True, cwd=peer)
    return time.perf_counter() - t0


def peer_verdicts(save_root: Path, hand: str) -> dict[str, dict]:
    """{file relative path: {succ, delta_pos, delta_angle}} of the peer's evaluation files."""
    ev = save_root / f"datagen_{hand}" / "evaluation"
    out = {}
    for p in sorted(ev.rglob("*.npy")):
        d = np.load(p, allow_pickle=True).item()
        out[str(p.relative_to(ev))] = {"succ": bool(d["succ_flag"]), "delta_pos": float(d["delta_pos"]),
                                       "delta_angle": float(d["delta_angle"])}
    return out


def our_verdicts(job: Path, hand_name: str, variant: str, cache: Path) -> dict[str, dict]:
    """{grasp_id: {succ, reason, rot, trans, steps}} of this project's evaluator under ``variant``."""
    if cache.is_file():
        return json.loads(cache.read_text())
    from datagen.eval import EvalConfig, Evaluator
    from datagen.eval.table import row_pieces, row_poses
    from datagen.hands import load_hand
    from datagen.io import read_job

    rows = read_job(job).to_pylist()
    out = {}
    t0 = time.process_time()
    with Evaluator(load_hand(hand_name), EvalConfig.from_dict(VARIANTS[variant])) as ev:
        for r in rows:
            res = ev.evaluate(row_pieces(r, job), row_poses(r), str(r["task"]))
            rot = [x for x in res.direction_rotation_deg if x == x]
            trans = [x for x in res.direction_translation_m if x == x]
            out[r["grasp_id"]] = {"succ": bool(res.success), "reason": res.reason, "steps": res.sim_steps,
                                  "rot": max(rot) if rot else None, "trans": max(trans) if trans else None,
                                  "object": r["object_id"], "scale": r["object_scale_m"]}
    out["_cpu_s"] = time.process_time() - t0
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps(out))
    return out


def _pct(a: int, n: int) -> str:
    return f"{a}/{n} ({100 * a / max(n, 1):.1f}%)"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--job", action="append", default=[], metavar="HAND=JOB", help="a hand the peer has, its job")
    ap.add_argument("--early-only", action="append", default=[], metavar="HAND=JOB",
                    help="a job whose early pass is compared with the full hold only")
    ap.add_argument("--peer", required=True, help="DexGraspBench checkout (1e7a5a6, Menagerie submodule)")
    ap.add_argument("--peer-python", required=True, help="Python of the peer's environment (mujoco 3.3.2)")
    ap.add_argument("--work", required=True, help="scratch folder: exports, the peer's outputs, cached verdicts")
    ap.add_argument("--peer-mj4", default="", help="optional: a copy of the peer made to run on this project's "
                    "MuJoCo (a diagnostic of the version's share of the disagreements), and --peer-mj4-python")
    ap.add_argument("--peer-mj4-python", default="")
    ap.add_argument("--workers", type=int, default=2, help="the peer's n_worker")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    work, peer = Path(args.work).resolve(), Path(args.peer).resolve()
    save_root = work / "peer_out"
    peer_commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                 cwd=peer).stdout.strip()
    peer_mujoco = subprocess.run([args.peer_python, "-c", "import mujoco; print(mujoco.__version__)"],
                                 capture_output=True, text=True).stdout.strip()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=ROOT).stdout.strip()
    machine = machine_description()
    rows, early, details, timing, mj4 = [], [], [], [], []
    for item in args.job + args.early_only:
        hand, _, job = item.partition("=")
        job = Path(job).resolve()
        ours = {v: our_verdicts(job, hand, v, work / "ours" / f"{hand}_{v.replace(' ', '_').replace(',', '')}.json")
                for v in VARIANTS}
        ids = [k for k in ours["default"] if not k.startswith("_")]
        a, b = ours["default"], ours["full hold"]
        fp = [g for g in ids if a[g]["succ"] and not b[g]["succ"]]
        ff = [g for g in ids if b[g]["succ"] and not a[g]["succ"]]
        early.append((hand, len(ids), sum(b[g]["succ"] for g in ids), fp, ff,
                      sum(a[g]["steps"] for g in ids) / max(1, sum(b[g]["steps"] for g in ids)),
                      a["_cpu_s"] / len(ids), b["_cpu_s"] / len(ids), [b[g] for g in fp]))
        if item not in args.job:
            continue
        files = export(job, save_root / f"datagen_{PEER_NAME[hand]}")
        wall = run_peer(peer, args.peer_python, PEER_NAME[hand], save_root, args.workers)
        theirs = peer_verdicts(save_root, PEER_NAME[hand])
        pairs = [(files[f], theirs[f]) for f in files if f in theirs]
        timing.append((hand, len(files), len(pairs), wall))
        row = [hand, len(pairs), sum(t["succ"] for _, t in pairs)]
        for v in VARIANTS:
            row.append((sum(ours[v][g]["succ"] for g, _ in pairs), sum(ours[v][g]["succ"] == t["succ"] for g, t in pairs)))
        rows.append(row)
        if args.peer_mj4:  # the same files under the peer's loop on this project's MuJoCo
            root4 = work / "peer_out_mj4"
            link = root4 / f"datagen_{PEER_NAME[hand]}" / "graspdata"
            if not link.exists():
                link.parent.mkdir(parents=True, exist_ok=True)
                link.symlink_to(save_root / f"datagen_{PEER_NAME[hand]}" / "graspdata")
            run_peer(Path(args.peer_mj4), args.peer_mj4_python, PEER_NAME[hand], root4, args.workers)
            t4 = peer_verdicts(root4, PEER_NAME[hand])
            both = [(files[f], theirs[f], t4[f]) for f in files if f in theirs and f in t4]
            mj4.append((hand, len(both), sum(c["succ"] for _, _, c in both),
                        sum(t["succ"] == c["succ"] for _, t, c in both),
                        {v: sum(ours[v][g]["succ"] == c["succ"] for g, _, c in both) for v in VARIANTS}))
        for g, t in pairs:
            o = ours["default"][g]
            if o["succ"] != t["succ"]:
                details.append((hand, o["object"], o["scale"], t["succ"], t["delta_pos"], t["delta_angle"], o["reason"],
                                o["rot"], o["trans"], ours["full hold"][g]["succ"]))

    cmd = "python -m benchmarks.bench_interop " + " ".join(
        [f"--job {j}" for j in args.job] + [f"--early-only {j}" for j in args.early_only]
        + ["--peer DGB --peer-python DGB_VENV/bin/python --work WORK"])
    lines = ["# Interop: this project's verdicts against DexGraspBench's own evaluator", "",
             f"Code {commit}; DexGraspBench {peer_commit} (its code unchanged; its hand files, MuJoCo Menagerie's LEAP "
             f"from its submodule) on mujoco {peer_mujoco}; this project on mujoco {mujoco.__version__}. Machine: "
             f"{machine}.", "", f"Command: `{cmd}` (benchmarks/bench_interop.py; the steps are in its docstring).", "",
             "## Success verdicts against the peer's", "",
             "Each cell: successes, then how many verdicts equal the peer's `succ_flag`.", "",
             "| hand | grasps | peer successes | " + " | ".join(f"ours: {v}" for v in VARIANTS) + " |",
             "|---|---|---|" + "---|" * len(VARIANTS)]
    for hand, n, ps, *vs in rows:
        lines.append(f"| {hand} | {n} | {ps} | " + " | ".join(f"{s} succ; agree {_pct(a, n)}" for s, a in vs) + " |")
    if mj4:
        lines += ["", f"The peer's loop on this project's MuJoCo ({mujoco.__version__}; a measurement copy of its code whose "
                  "only change is the weld's `data`, 11 -> 12 values as MuJoCo 4 wants): how much of the disagreement "
                  "is the MuJoCo version.", "",
                  "| hand | grasps | its successes | agrees with itself on 3.3.2 | " + " | ".join(
                      f"ours: {v}, agree" for v in VARIANTS) + " |", "|---|---|---|---|" + "---|" * len(VARIANTS)]
        for hand, n, succ, same, by in mj4:
            lines.append(f"| {hand} | {n} | {succ} | {_pct(same, n)} | " + " | ".join(_pct(by[v], n) for v in VARIANTS) + " |")
    lines += ["", "Peer cost: " + "; ".join(f"{h} {p} of {f} files evaluated, {w:.0f} s wall with {args.workers} workers"
                                           for h, f, p, w in timing) + ".", ""]
    if details:
        lines += ["Disagreements under the default (peer's delta at its last check; ours: the largest over the "
                  "directions simulated):", "",
                  "| hand | object | scale m | peer succ | peer delta mm | peer delta deg | our reason | our deg | our mm | "
                  "our full hold |", "|---|---|---|---|---|---|---|---|---|---|"]
        for h, o, s, ps, dp, da, r, rot, tr, full in details:
            lines.append(f"| {h} | {o} | {s:.3f} | {ps} | {dp * 1000:.1f} | {da:.2f} | {r} | "
                         f"{'' if rot is None else f'{rot:.2f}'} | {'' if tr is None else f'{tr * 1000:.1f}'} | {full} |")
        lines.append("")
    lines += ["## Early pass against the full hold (the default protocol)", "",
              "| hand | rows | successes (full hold) | false passes | false fails | steps, early / full | "
              "CPU s per grasp, early / full |", "|---|---|---|---|---|---|---|"]
    for hand, n, succ, fp, ff, steps, ce, cf, _ in early:
        lines.append(f"| {hand} | {n} | {succ} | {len(fp)} | {len(ff)} | {steps:.3f} | {ce:.3f} / {cf:.3f} |")
    fps = [(h, r) for h, *_, rs in early for r in rs]
    if fps:
        lines += ["", "False passes (the full hold's failing figures): " + "; ".join(
            f"{h} {r['object']} {r['scale']:.2f} m: {r['reason']}, {r['rot']:.3f} deg, {r['trans'] * 1000:.1f} mm"
            for h, r in fps) + "."]
    kept = hand_notes(args.out)
    write_report(args.out, lines + ([""] + kept if kept else []) + [""])


if __name__ == "__main__":
    main()
