"""Grasp quality on real objects: the default force-closure job, per hand x scale x object family.

Runs the product itself, ``datagen run`` (Ray, the default job config, nothing relaxed) on the
real-object development set ``manifests/real_dev.jsonl`` (household meshes from pybullet,
metaworld and MyoSuite, ``make real-objects``) for each hand, then reads the job's rows. Every
synthesized pose is a row: a pose rejected before simulation counts as a failure with its reason.

Reported per hand x scale and per object family: six-direction success, the share of poses in
force closure at synthesis (synthesis epsilon > 0), MuJoCo's epsilon at the grasp, the successes'
penetration at the grasp (p90, mm), successes without any touching link (must be 0), synthesis
seconds per grasp (failure mechanisms: `benchmarks/diagnose_sizes.py`), and per scale the
successes' diversity
(`datagen.eval.diversity`: DexGraspBench's PCA explained-variance ratio, GraspQP's mean joint
entropy). Writes ``benchmarks/results/quality.md`` ending with
``quality: shadow=S e3m5=E allegro=A leap=L`` (percent over the default job's scales) and a
``quality per scale:`` line. The page's hand-written sections (between the title and
``## Tables``, and from ``## Notes``) are kept.

Usage: ``make bench-quality`` or ``python -m benchmarks.bench_quality --hands shadow --grasps 8``;
``--objects 25 --scales 0.06,0.08,0.1,0.12,0.15`` runs every development object at those sizes
(on a copy of the manifest); ``--synth '{"seeds_per_grasp": 1}'`` runs a variant (its rows are
reported but it does not write the page unless the variant is empty).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.common import machine_description
from datagen.io import read_job
from datagen.objects.manifest import load_manifest
from workers.job import JobConfig, JobDir, code_version

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "manifests" / "real_dev.jsonl"
RESULTS = ROOT / "benchmarks" / "results" / "quality.md"
HANDS = {"shadow": "shadow", "shadow_e3m5": "e3m5", "allegro": "allegro", "leap": "leap"}
COLUMNS = ["object_id", "object_scale_m", "success", "reason", "synth_epsilon", "epsilon", "penetration_m",
           "touching_links"]


def run_job(hand: str, out: Path, grasps: int, objects: int, synth: dict, manifest: Path = MANIFEST,
            num_cpus: int | None = None) -> None:
    """``datagen run`` of the default force-closure job for ``hand`` (resumes a finished job);
    ``num_cpus``: the job's worker CPUs (None: every core)."""
    cmd = [sys.executable, "-m", "datagen.cli", "run", "--out", str(out), "--manifest", str(manifest),
           "--objects", str(objects), "--hand", hand, "--tasks", "force_closure", "--grasps", str(grasps),
           "--no-progress"] + (["--num-cpus", str(num_cpus)] if num_cpus else [])
    if synth:
        cfg = out.with_suffix(".yaml")
        cfg.parent.mkdir(parents=True, exist_ok=True)
        cfg.write_text(json.dumps({"synth": synth}))  # over the default recipe (datagen.pipeline.resolve)
        cmd += ["--config", str(cfg)]
    subprocess.run(cmd, check=True, cwd=ROOT)


def with_scales(manifest: Path, scales: tuple[float, ...], work: Path) -> Path:
    """A copy of ``manifest`` whose every entry has ``scales`` (metres), in ``work``."""
    lines = [json.loads(x) for x in manifest.read_text().splitlines() if x.strip()]
    out = work / f"{manifest.stem}-s{'_'.join(f'{s:g}' for s in scales)}.jsonl"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("".join(json.dumps({**x, "scales": list(scales)}, sort_keys=True) + "\n" for x in lines))
    return out


def summarize(rows: dict, sel: np.ndarray) -> dict:
    ok = np.asarray(rows["success"], dtype=bool)[sel]
    pen = np.asarray(rows["penetration_m"], dtype=float)[sel]
    touch = np.asarray(rows["touching_links"])[sel]
    return {"n": int(sel.sum()), "success": 100 * float(ok.mean()) if ok.size else float("nan"),
            "fc": 100 * float((np.asarray(rows["synth_epsilon"], dtype=float)[sel] > 0).mean()) if ok.size else float("nan"),
            "eps": float(np.median(np.asarray(rows["epsilon"], dtype=float)[sel])) if ok.size else float("nan"),
            "pen90": 1000 * float(np.percentile(pen[ok], 90)) if ok.any() else float("nan"),
            "no_touch": int((touch[ok] == 0).sum())}


def diversity_lines(hand: str, rows: dict, scales: np.ndarray) -> list[str]:
    """Per scale, the successes' diversity (`datagen.eval.diversity`): DexGraspBench's PCA
    explained-variance ratio (top 1..5 components; lower = more diverse) and GraspQP's mean joint
    entropy (nats; max ln 32 = 3.47)."""
    from datagen.eval.diversity import grasp_diversity
    from datagen.hands import load_hand

    h = load_hand(hand)
    lo, hi = h.joint_lower.cpu().numpy(), h.joint_upper.cpu().numpy()
    ok = np.asarray(rows["success"], dtype=bool)
    q = np.asarray(rows["grasp_qpos"], dtype=np.float64)
    out = ["| successes (diversity) | n | PCA explained variance, top 1 / 2 / 3 / 4 / 5 | mean joint entropy |",
           "|---|---|---|---|"]
    for name, sel in [("all", ok)] + [(f"scale {s:g} m", ok & (scales == s)) for s in sorted(set(scales.tolist()))]:
        d = grasp_diversity(q[sel], lo, hi)
        out.append(f"| {name} | {d.n} | " + " / ".join(f"{x:.2f}" for x in d.pca) + f" | {d.joint_entropy:.2f} |")
    return out


def hand_section(hand: str, job: Path, grasps: int, families: dict) -> tuple[list[str], dict]:
    """The page's section of one hand's job and its success per scale."""
    rows = read_job(job, columns=COLUMNS + ["grasp_qpos"]).to_pydict()
    ledger = list(JobDir(job).audit().finished.values())  # the shards' ledger entries
    synth_s = sum(x["timings"].get("synth_s", 0) for x in ledger)
    shard_wall = sum(x.get("wall_s", 0) for x in ledger)
    n = len(rows["success"])
    scales = np.round(np.asarray(rows["object_scale_m"], dtype=float), 4)
    fam = np.array([families.get(o, "?") for o in rows["object_id"]])
    default = np.isin(scales, np.round(np.asarray(JobConfig().scales, dtype=float), 4))
    per_scale = {s: summarize(rows, scales == s)["success"] for s in sorted(set(scales.tolist()))}
    per_scale["default"] = summarize(rows, default)["success"]
    lines = [f"### {hand}", "",
             f"{n} poses ({grasps} per object and scale); shard wall time {shard_wall:.0f} s in all, of which "
             f"synthesis {synth_s / max(n, 1):.2f} s per grasp (shards ran 2 at a time on a machine shared "
             "with other work).", "",
             "| rows | n | success % | force closure at synthesis % | MuJoCo epsilon (median) | "
             "successes' penetration p90 mm | successes without contact |", "|---|---|---|---|---|---|---|"]

    def row(name, s):
        return (f"| {name} | {s['n']} | {s['success']:.1f} | {s['fc']:.0f} | {s['eps']:.3f} | {s['pen90']:.2f} | "
                f"{s['no_touch']} |")

    lines.append(row("all", summarize(rows, np.ones(n, dtype=bool))))
    lines += [row(f"scale {s:g} m", summarize(rows, scales == s)) for s in sorted(set(scales.tolist()))]
    lines += ["", "By family (success %, rows): " + ", ".join(
        f"{f} {summarize(rows, fam == f)['success']:.0f} ({int((fam == f).sum())})" for f in sorted(set(fam.tolist())))
              + ".", ""] + diversity_lines(hand, rows, scales) + [""]
    print(f"{hand}: {summarize(rows, np.ones(n, dtype=bool))['success']:.1f}% of {n}", flush=True)
    return lines, per_scale


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hands", default=",".join(HANDS), help="comma-separated hands")
    ap.add_argument("--grasps", default="shadow=8,shadow_e3m5=4,allegro=4,leap=4",
                    help="grasps per object and scale, per hand (HAND=N,...; a plain N for every hand)")
    ap.add_argument("--objects", type=int, default=14, help="objects of the manifest (first N)")
    ap.add_argument("--scales", default=None,
                    help="comma-separated object scales, metres, for every object (default: the manifest's)")
    ap.add_argument("--synth", default="{}", help="JSON SynthConfig overrides on the default job (a variant)")
    ap.add_argument("--work", type=Path, default=ROOT / ".cache" / "bench_quality", help="job directories")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--num-cpus", type=int, default=None, help="worker CPUs of each job (default: every core)")
    ap.add_argument("--code", default=None, help="reuse the jobs made at this code version (default: this checkout's)")
    args = ap.parse_args()
    synth = json.loads(args.synth)
    per_hand = {"*": int(args.grasps)} if args.grasps.isdigit() else {
        k: int(v) for k, v in (x.split("=") for x in args.grasps.split(","))}
    commit = args.code or code_version()
    families = {e.id: e.family for e in load_manifest(MANIFEST)}
    scales_arg = tuple(float(x) for x in args.scales.split(",")) if args.scales else None
    manifest = with_scales(MANIFEST, scales_arg, args.work) if scales_arg else MANIFEST
    lines = [TABLES, "",
             f"Code {commit}; machine: {machine_description()}.", "",
             f"Objects: `manifests/real_dev.jsonl`, the first {args.objects}"
             + (f", every one at {', '.join(f'{s:g}' for s in scales_arg)} m" if scales_arg else "")
             + ". Each hand runs the default `datagen run` job (`--tasks force_closure`, the job's default synthesis "
             "and evaluation, the unchanged six-direction MuJoCo test: 1 N for 2 s per direction, < 5 cm and "
             "< 15 deg). Every synthesized pose is a row; rejections count as failures."
             + (f" Variant: synth {synth}." if synth else ""), ""]
    headline = {}
    for hand in args.hands.split(","):
        grasps = per_hand[hand] if hand in per_hand else per_hand.get("*", 8)
        tag = "" if not synth else "-" + "-".join(f"{k}{v}" for k, v in sorted(synth.items()))
        if scales_arg:
            tag += "-s" + "_".join(f"{s:g}" for s in scales_arg)
        job = args.work / f"{hand}-{commit}-g{grasps}-o{args.objects}{tag}"
        run_job(hand, job, grasps, args.objects, synth, manifest, args.num_cpus)
        section, headline[hand] = hand_section(hand, job, grasps, families)
        lines += section
    head, notes = _kept(args.out)
    lines = [TITLE, ""] + head + lines + notes
    if not synth:
        lines.append(f"Headline: six-direction success over the default job's scales {JobConfig().scales} m on the "
                     f"objects above; the per-scale line covers every scale run.")
        lines.append("quality: " + " ".join(f"{HANDS[h]}={headline[h]['default']:.1f}" if h in headline
                                            else f"{HANDS[h]}=n/a" for h in HANDS))
        lines.append("quality per scale: " + "; ".join(
            f"{HANDS[h]} " + " ".join(f"{s:g}={v:.1f}" for s, v in headline[h].items() if s != "default")
            for h in HANDS if h in headline))
        args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines[-2:]))


TITLE = "# Grasp quality on real objects (default force-closure job)"
TABLES = "## Tables (`make bench-quality`)"


def _kept(path: Path) -> tuple[list[str], list[str]]:
    """The hand-written sections kept across runs: the one between the title and the tables
    (e.g. a diagnosis), and the notes (from '## Notes' to the machine-readable lines)."""
    if not path.is_file():
        return [], []
    text = path.read_text().splitlines()
    end = text.index(TABLES) if TABLES in text else next((i for i, x in enumerate(text) if x.startswith("## ")),
                                                         len(text))
    head = text[1:end]
    while head and not head[0].strip():
        head = head[1:]
    notes = text[text.index("## Notes"):] if "## Notes" in text else []
    return head if TABLES in text else [], [x for x in notes if not x.startswith(("quality", "Headline: "))]


if __name__ == "__main__":
    main()
