"""Task-oriented benchmark (paper §V-B, Tables II and its hyper-parameter table).

Per task (the ten built-in task YAMLs and their objects from `datagen.objects.task_objects`):
``--num`` poses x ``--iters`` iterations with each variant, every pose evaluated in MuJoCo by
the task's own test (``eval`` block of its YAML: the disturbance -w_t on the object's virtual
joint, or the six-direction hold test for precision grasps). Variants:

- ``baseline``: no task energy (weight 0); ``l2``: L2 task energy; ``nocpn``: no contact
  position normalization; ``full``: the method (delta 15 deg, K = 1e2) -- Table II;
- ``d0_k1e2``, ``d15_k1e4``, ``d0_k1e4``: the hyper-parameter rows (delta, K);
- ``baseline_ms``, ``full_ms``: baseline and full with 8 seeds per pose (multi-start as
  force-closure synthesis runs it; the best seed after 120 iterations goes on).

Two initialisation regimes (``--inits``): ``task``, each task YAML's own initial poses (aimed,
pre-shaped), and ``generic``, one regime shared by every task and variant: the force-closure
synthesis's (palm towards the object from a random point of its convex hull inflated 3-6 cm,
roll +-180 deg, tilt +-15 deg, fingers open; `datagen.tasks.InitConfig` defaults), the regime
in which the task energy alone must bring the fingertips to where the task wrench is resisted.

Besides pass/fail at the task's magnitude, each pose's largest held multiple of the task's
disturbance (`datagen.eval.Evaluator.margin`: bisection on quarter octaves 0.25..32, octaves
before 2026-11-27; same thresholds) is recorded; the report gives its median and quartiles per
task and variant, and whether the full method's poses hold more than the baseline's (median, and
a one-sided Mann-Whitney test).

Each (hand, variant, task, num, iters) run is stored as a JSON record under ``--records``
(resumable: existing records are reused unless ``--force``); the report
``benchmarks/results/tasks.md`` is rendered from every record there, so partial runs
(``--tasks``, ``--variants``, ``--hands``, ``--num``) add up. Time = synthesis wall time; memory
= peak RSS above the process's RSS before that synthesis (sampled every 20 ms).
Usage: ``make bench-tasks`` (``BENCH_TASKS_ARGS=...``). It ends with the line
``tasks-generic: full=F baseline=B`` (ten-task averages, generic initialisation, with N).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import os
import threading
import time
from pathlib import Path

import numpy as np
import torch

RESULTS = Path(__file__).parent / "results" / "tasks.md"
RECORDS = Path(__file__).parent.parent / ".cache" / "bench_tasks"  # raw records (git-ignored)

TASKS = ("turn_handle", "turn_knob2", "turn_knob3", "lift_handbag", "lift_plate", "push_button", "pull_drawer",
         "precision_lid", "precision_key", "precision_usba")
COLUMNS = ("Handle", "Knob2", "Knob3", "Handbag", "Plate", "Button", "Drawer", "Lid", "Key", "USBA")
# Paper Table II (Shadow hand, Isaac Gym), per task in TASKS order, and the average.
PAPER = {"baseline": ([13, 39, 44, 0, 25, 40, 10, 38, 27, 2], 23.8),
         "l2": ([84, 60, 64, 10, 80, 91, 48, 97, 68, 62], 66.4),
         "nocpn": ([79, 64, 72, 50, 24, 96, 99, 86, 19, 2], 59.1),
         "full": ([75, 73, 58, 51, 97, 97, 99, 74, 62, 40], 72.6)}
# Paper hyper-parameter table: success %, time s, memory GB (RTX 3090).
PAPER_HYPER = {"full": (72.6, 14.9, 1.5), "d15_k1e4": (75.1, 83.5, 15.3), "d0_k1e2": (72.1, 14.5, 1.5),
               "d0_k1e4": (74.8, 83.4, 15.3)}
VARIANTS = {  # name -> (label, SynthConfig overrides)
    "baseline": ("Baseline (E_t weight 0)", {"weights": {"task": 0.0}}),
    "l2": ("Ablation1: L2 task energy", {"task_energy_kind": "l2"}),
    "nocpn": ("Ablation2: no CPN", {"contact": {"normalize": False}}),
    "full": ("Ours (cos, CPN, delta 15, K 1e2)", {}),
    "d0_k1e2": ("Ablation4: delta 0, K 1e2", {"contact": {"delta_deg": 0.0}}),
    "d15_k1e4": ("Ablation3: delta 15, K 1e4", {"num_directions": 10_000}),
    "d0_k1e4": ("Ablation5: delta 0, K 1e4", {"contact": {"delta_deg": 0.0}, "num_directions": 10_000}),
    # multi-start as force-closure synthesis runs it (8 seeds per pose, the best after 120
    # iterations kept): by the lowest total energy for gamma < 180 deg, where E_t is most of it
    # once the fingertips touch; by whole-hand epsilon for gamma = 180 (datagen.synth.select)
    "baseline_ms": ("Baseline, 8 seeds", {"weights": {"task": 0.0}, "seeds_per_grasp": 8}),
    "full_ms": ("Ours, 8 seeds", {"seeds_per_grasp": 8}),
    # twice the task specs' 16 seeds per pose: what more starts buy where few of them reach the
    # task's contact region (generic initialisation: the drawer's bar, the handbag's strap)
    "baseline_s32": ("Baseline, 32 seeds", {"weights": {"task": 0.0}, "seeds_per_grasp": 32}),
    "full_s32": ("Ours, 32 seeds", {"seeds_per_grasp": 32}),
}
TABLE_VARIANTS = ("baseline", "baseline_ms", "baseline_s32", "l2", "nocpn", "full", "full_ms", "full_s32")


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


class PeakRSS:
    """Context manager: ``peak_mb`` = the highest RSS seen above the RSS at entry (20 ms sampling)."""

    def __enter__(self):
        self.base, self.peak, self._stop = _rss_mb(), 0.0, threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()
        return self

    def _run(self):
        while not self._stop.wait(0.02):
            self.peak = max(self.peak, _rss_mb())

    def __exit__(self, *exc):
        self._stop.set()
        self._t.join()
        self.peak = max(self.peak, _rss_mb())
        self.peak_mb = self.peak - self.base


def synth_config(variant: str, iters: int, hand_name: str, seed: int, no_self_pen: bool, task_name: str):
    """The variant's `SynthConfig`: the ``paper`` preset's recipe of the task (its ``synth`` block
    over the library defaults), the variant's overrides on top (`datagen.pipeline.resolve`)."""
    from datagen.pipeline import resolve

    d = dict(VARIANTS[variant][1], iters=iters, seed=seed)
    if no_self_pen:
        d["weights"] = {**d.get("weights", {}), "self_penetration": 0.0}
    return resolve(hand_name, task_name, preset="paper", flags={"synth": d}).synth


class Objects:
    """Processed task objects and their synthesis targets, built once per process."""

    def __init__(self):
        self._cache = {}

    def get(self, name: str):
        if name not in self._cache:
            from datagen.eval.scene import pieces_from_processed
            from datagen.objects import task_objects
            from datagen.objects.process import process_object
            from datagen.objects.sources import iter_source
            from datagen.synth import GraspTarget

            ref = next(r for r in iter_source("tasks") if r.path == name)
            p = process_object(ref)
            if not p.ok:
                raise RuntimeError(f"task object {name}: {p.reason}: {p.message}")
            scale = task_objects.build(name).scale_m
            self._cache[name] = (GraspTarget.from_processed(p, scale), pieces_from_processed(p, scale))
        return self._cache[name]


STRESS = (3, 10)  #: disturbance multipliers of the robustness columns of older records
INITS = ("task", "generic")  #: initialisation regimes (see the module docstring)


def task_for(task_name: str, init: str):
    """The task spec of ``task_name`` with its own initial poses (``task``) or the generic ones."""
    from datagen.tasks import InitConfig, load_task

    spec = load_task(task_name)
    if init == "generic":  # every hand starts as for force closure: its `hands:` init fields go, its fingers stay
        return dataclasses.replace(spec, init=InitConfig(),
                                   hands={h: dataclasses.replace(o, init={}) for h, o in spec.hands.items()})
    if init != "task":
        raise SystemExit(f"unknown init {init!r}; known: {list(INITS)}")
    return spec


def code_version() -> str:
    """``git describe --always`` of this checkout, ``-dirty`` when files other than the benchmark
    results (which this script rewrites) differ from it; or $DATAGEN_CODE_VERSION (e.g. in an export)."""
    import subprocess

    if os.environ.get("DATAGEN_CODE_VERSION"):
        return os.environ["DATAGEN_CODE_VERSION"]

    def git(*args):
        return subprocess.run(["git", *args], cwd=Path(__file__).parent, text=True, capture_output=True,
                              check=True).stdout.strip()

    try:
        changed = git("status", "--porcelain", "--untracked-files=no", "--", ":/", ":(exclude,top)benchmarks/results")
        return git("describe", "--always") + ("-dirty" if changed else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def run_record(hand, task_name: str, variant: str, num: int, iters: int, objects: Objects, seed: int,
               no_self_pen: bool, init: str = "task") -> dict:
    """Synthesize ``num`` poses of one task with one variant and evaluate each; a JSON-able record."""
    from datagen.eval import MULTIPLES, EvalConfig, Evaluator
    from datagen.synth import synthesize
    from datagen.tasks import task_object

    task = task_for(task_name, init)
    target, pieces = objects.get(task_object(task))
    cfg = synth_config(variant, iters, hand.name, seed, no_self_pen, task_name)
    with PeakRSS() as mem:
        t0 = time.perf_counter()
        res = synthesize(hand, [target], task, cfg, num)
        synth_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    reasons, success, held = [], [], []
    poses = [torch.stack([res.pregrasp[b], res.grasp[b], res.squeeze[b]]).double().numpy() for b in range(num)]
    with Evaluator(hand, EvalConfig()) as ev:
        for p in poses:
            m = ev.margin(pieces, p, task=task_name, w_t=task.w_t)
            reasons.append(m.result.reason)
            success.append(bool(m.result.success))
            held.append(m.held_multiple)
    eval_s = time.perf_counter() - t0
    usable = res.usable(cfg.contact_threshold_m)
    e_task = final_task_energy(task, res.contact_points, res.contact_normals)
    return {"hand": hand.name, "task": task_name, "variant": variant, "init": init, "num": num, "iters": iters,
            "seed": seed, "no_self_penetration": no_self_pen, "fingers": res.fingers,
            "success": float(np.mean(success)), "reasons": dict(collections.Counter(reasons)),
            "held_multiple": held, "multiples": list(MULTIPLES), "success_per_pose": success,
            "e_task": None if e_task is None else [float(x) for x in e_task],
            "synth_s": synth_s, "eval_s": eval_s, "peak_mb": mem.peak_mb,
            "tips_in_contact": float(usable.float().mean()),
            "max_penetration_mm_median": float(res.max_penetration.median()) * 1e3,
            "code_version": code_version(), "finished_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def final_task_energy(task, points: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """(B,) the full method's E_t (mean cosine; cos, CPN, delta 15 deg, mu 0.5, 1000 fixed directions)
    at the synthesized contacts, for every variant (the baseline's included): how task-aligned
    its poses are, whatever it optimized."""
    from datagen.wrench import sample_directions, task_energy

    dirs = sample_directions(1000, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    with torch.no_grad():
        return task_energy(points.double(), normals.double(), 0.5, list(task.w_t), task.gamma_deg, dirs) / 1000


def record_path(records: Path, hand: str, variant: str, task: str, num: int, iters: int, init: str = "task") -> Path:
    tag = "" if init == "task" else f"__{init}"
    return records / f"{code_version()}__{hand}__{variant}__{task}__n{num}__i{iters}{tag}.json"


# ----------------------------------------------------------------------------- report
def _load(records: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(records.glob("*.json"))]


def _pick(recs, hand, variant, task, init="task"):
    """The record with the most poses (then iterations) for (hand, variant, task, init)."""
    c = [r for r in recs if (r["hand"], r["variant"], r["task"], r.get("init", "task")) == (hand, variant, task, init)]
    return max(c, key=lambda r: (r["num"], r["iters"])) if c else None


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f}"


def task_definitions() -> list[str]:
    """The tasks as their YAMLs and objects define them (one row per task)."""
    from datagen.eval import EvalConfig
    from datagen.tasks import task_object
    from datagen.objects import task_objects
    from datagen.tasks import load_task

    cfg = EvalConfig()
    out = ["## Tasks (from `datagen/tasks/specs/*.yaml` and `datagen/objects/task_objects.py`)", "",
           "| task | object (scale m) | joint | w_t | gamma | fingers | init approach / aim (m) | test: disturbance, pass |",
           "|---|---|---|---|---|---|---|---|"]
    for t in TASKS:
        spec = load_task(t)
        obj = task_objects.build(task_object(spec))
        test = cfg.task_test(t)
        if test is None:
            dist = f"six directions, {cfg.force_per_kg * cfg.object_mass_kg:g} N; < {cfg.max_translation_m * 100:g} cm, < {cfg.max_rotation_deg:g} deg"
        else:
            w = test.disturbance(cfg.object_mass_kg, obj.scale_m, cfg.force_per_kg)
            tr = test.max_translation_m or cfg.max_translation_m
            rot = test.max_rotation_deg or cfg.max_rotation_deg
            dist = (f"[{', '.join(f'{x:g}' for x in np.round(w, 4) + 0.0)}] N, N m; < {tr * 100:g} cm, < {rot:g} deg "
                    f"from the {test.measure_from} pose")
        j = obj.joint
        joint = j.kind if j.kind == "free" else f"{j.kind} {list(j.axis)} @ {list(j.anchor_m)}"
        if j.limits is not None:
            joint += ", stops " + " / ".join("none" if x is None else f"{x:+g}" for x in j.limits)
        n = len(obj.scenery_m)
        scenery = f"; scenery: {n} box{'es' if n > 1 else ''}" if n else ""
        out.append(f"| {t} | {obj.name} ({obj.scale_m:.3f}{scenery}) | {joint} | {list(spec.w_t)} | {spec.gamma_deg:g} | "
                   f"{', '.join(spec.fingers)} | {list(spec.init.approach)} / {list(spec.init.target_m)} | {dist} |")
    return out


def render(records: Path, machine: str) -> str:
    allrecs = _load(records)
    versions = sorted({r.get("code_version", "-") for r in allrecs},
                      key=lambda v: min(r["finished_at"] for r in allrecs if r.get("code_version", "-") == v))
    lines = ["# Task-oriented benchmark (paper Table II and its hyper-parameter table)", "",
             f"Machine: {machine}", "",
             "Ten tasks on procedural objects with virtual joints (`datagen/objects/task_objects.py`); the mounted ones "
             "(lever, knobs, button, drawer) in their static scenery since `a8b9d26` (door, panel, housing, cabinet: "
             "boxes the hand must stay out of, in synthesis and in MuJoCo; earlier versions had none), task specs "
             "`datagen/tasks/specs/<task>.yaml` (TWS, fingers, initial pose, and the `eval` block each task's test "
             "comes from). Success = MuJoCo task test: the disturbance -w_t (magnitudes per task in its YAML) on the "
             "object's virtual joint, object unmoved (per-task thresholds in the YAML); precision grasps: the "
             "six-direction hold test (1 N, 5 cm / 15 deg from the initial pose). Task tests measure the object's motion from "
             "its pose once the hand has closed (the paper: hand fixed at the grasp, wrench applied, object unmoved). Paper numbers: Shadow hand, Isaac Gym, RTX 3090. "
             "Each cell: success % (poses per task in its row, iterations in the runs table). Two initialisation regimes: "
             "task-specific (each YAML's `init`) and generic (force closure's: palm towards the inflated convex hull, "
             "the same for every task and variant); a task YAML's `synth` block (e.g. exact contacts, 8 seeds) applies "
             "to every variant, which only override their own settings. Held task wrench: per pose, the largest "
             "multiple of the disturbance held (`Evaluator.margin`). Per hand and initialisation the page shows the "
             "latest code version whose records cover every task, newest first; earlier results are in git "
             "(`git log -p benchmarks/results/tasks.md`). Command: `make bench-tasks` (`python -m benchmarks.bench_tasks`).", ""]
    lines += task_definitions() + [""]
    latest = latest_complete(allrecs, versions)
    for version in sorted(set(latest.values()), key=versions.index, reverse=True):
        recs = [r for r in allrecs if r.get("code_version", "-") == version
                and latest.get((r["hand"], r.get("init", "task"))) == version]
        lines += [f"{RESULTS_HEADING}{version}", ""]
        lines += _render_version(recs)
    return "\n".join(lines)


def latest_complete(recs: list[dict], versions: list[str]) -> dict[tuple[str, str], str]:
    """(hand, init) -> the newest code version (``versions`` oldest first) with a record of the
    full method on every task, else the newest with any record."""
    out = {}
    for key in {(r["hand"], r.get("init", "task")) for r in recs}:
        mine = [r for r in recs if (r["hand"], r.get("init", "task")) == key]
        have = [v for v in versions if any(r.get("code_version", "-") == v for r in mine)]
        full = [v for v in have if {r["task"] for r in mine if r.get("code_version", "-") == v
                                    and r["variant"] == "full"} >= set(TASKS)]
        out[key] = (full or have)[-1]
    return out


def _held_cell(c) -> str:
    """``median [p25, p75]`` of a record's held multiples, '-' without them."""
    if not c or "held_multiple" not in c:
        return "-"
    q = np.percentile(c["held_multiple"], [50, 25, 75], method="lower")
    return f"{q[0]:.3g} [{q[1]:.3g}, {q[2]:.3g}]"


def _grid_name(cells) -> str:
    """The held-multiple grid(s) the records ran on, in words."""
    from datagen.eval import OCTAVE_MULTIPLES  # the grid of the records that do not name theirs

    names = set()
    for c in cells:
        if c and "held_multiple" in c:
            g = np.log2(c.get("multiples") or OCTAVE_MULTIPLES)
            step = np.diff(g).min() if len(g) > 1 else 1.0
            kind = "octaves" if np.isclose(step, 1.0) else f"1/{1 / step:.0f} octaves"
            names.add(f"{kind} {2 ** g[0]:g}..{2 ** g[-1]:g}")
    return "; ".join(sorted(names)) or "-"


def held_comparison(full, base) -> tuple[str, bool, float] | None:
    """Full vs baseline held multiples of one task: (cell, median higher, one-sided p).

    p: the Mann-Whitney U test's, alternative "full's held multiples are stochastically larger"
    (ties counted by the usual mid-rank correction); None without both records."""
    from scipy.stats import mannwhitneyu

    if not (full and base and "held_multiple" in full and "held_multiple" in base):
        return None
    f, b = np.asarray(full["held_multiple"], float), np.asarray(base["held_multiple"], float)
    mf, mb = (float(np.percentile(x, 50, method="lower")) for x in (f, b))
    p = 1.0 if np.all(f == f[0]) and np.all(b == f[0]) else float(mannwhitneyu(f, b, alternative="greater").pvalue)
    word = "higher" if mf > mb else "tie" if mf == mb else "lower"
    return f"{word} (p {p:.2g})", mf > mb, p


#: the variant pairs the held table compares, (full, baseline, row label)
COMPARED = (("full", "baseline", "Ours vs baseline"), ("full_s32", "baseline_s32", "Ours vs baseline, 32 seeds"))


def _comparison_row(pick, pair=COMPARED[0]) -> tuple[str, str] | None:
    """A held-table row comparing ``pair`` (per task: median higher / tie / lower, p) and its summary."""
    full, base, label = pair
    cmp = [held_comparison(pick(full, t), pick(base, t)) for t in TASKS]
    if not any(cmp):
        return None
    got = [x for x in cmp if x]
    higher = sum(x[1] for x in got)
    sig = sum(x[2] < 0.05 for x in got)
    row = f"| {label}: median, one-sided p | " + " | ".join(x[0] if x else "-" for x in cmp) + " |"
    return row, (f"median held higher than the baseline's on {higher} of {len(got)} tasks, the poses hold more "
                 f"(one-sided Mann-Whitney p < 0.05) on {sig} of {len(got)}")


def _sizes(cells) -> str:
    ns = sorted({c["num"] for c in cells if c})
    return "/".join(str(n) for n in ns) if ns else "-"


def _energy_vs_test(pick, hand: str, what: str, cut: float = -0.5) -> list[str]:
    """Does E_t measure what the test needs? Per task, every variant's poses pooled: success
    among poses whose final E_t (the full method's, ``final_task_energy``) is <= ``cut`` and
    among the others, and the rank correlation of E_t with the held multiple."""
    rows = []
    for t, col in zip(TASKS, COLUMNS):
        e, ok, held = [], [], []
        for v in TABLE_VARIANTS:
            c = pick(v, t)
            if c and c.get("e_task") and "success_per_pose" in c and len(c["e_task"]) == len(c["success_per_pose"]):
                e += c["e_task"]
                ok += c["success_per_pose"]
                held += c["held_multiple"]
        if not e:
            continue
        e, ok, held = np.array(e), np.array(ok, dtype=float), np.array(held)
        lo = e <= cut
        rank = lambda x: np.argsort(np.argsort(x, kind="stable"), kind="stable")  # noqa: E731
        rho = np.corrcoef(rank(e), rank(held))[0, 1] if e.std() > 0 and held.std() > 0 else float("nan")
        pct = lambda m: f"{100 * ok[m].mean():.0f} ({int(m.sum())})" if m.any() else "- (0)"  # noqa: E731
        rows.append(f"| {col} | {pct(lo)} | {pct(~lo)} | {rho:+.2f} |")
    if not rows:
        return []
    return [f"### E_t and the test: {hand}, {what}", "",
            f"All variants' poses of each task pooled; E_t = the full method's task energy (mean cosine, "
            f"1000 fixed directions) at each pose's final contacts. Success % (poses) with E_t <= {cut} and "
            "> cut; Spearman rank correlation of E_t with the held multiple (negative: lower E_t, more held).", "",
            f"| task | success, E_t <= {cut} | success, E_t > {cut} | rho(E_t, held) |", "|---|---|---|---|",
            *rows, ""]


def _render_version(recs: list[dict]) -> list[str]:
    lines = []
    hands = sorted({r["hand"] for r in recs}, key=lambda h: (h != "shadow", h))
    for hand in hands:
        for init in INITS:
            if not any(r.get("init", "task") == init and r["hand"] == hand for r in recs):
                continue
            lines += _render_hand(recs, hand, init)
    return lines


def _render_hand(recs: list[dict], hand: str, init: str) -> list[str]:
    lines = []
    pick = lambda v, t: _pick(recs, hand, v, t, init)  # noqa: E731
    what = {"task": "task-specific initial poses", "generic": "generic initial poses (force closure's)"}[init]
    lines += [f"## Table II: {hand}, {what}", "",
              "| variant | " + " | ".join(COLUMNS) + " | average | poses per task | paper average |",
              "|---|" + "---|" * (len(COLUMNS) + 3)]
    for v in TABLE_VARIANTS:
        cells = [pick(v, t) for t in TASKS]
        if not any(cells):
            continue
        got = [c["success"] for c in cells if c]
        avg = f"{100 * np.mean(got):.1f}" + ("" if len(got) == len(TASKS) else f" ({len(got)} tasks)")
        paper = PAPER[v][1] if hand == "shadow" and v in PAPER else "-"
        lines.append(f"| {VARIANTS[v][0]} | " + " | ".join(_pct(c and c["success"]) for c in cells)
                     + f" | {avg} | {_sizes(cells)} | {paper} |")
        if hand == "shadow" and v in PAPER:
            lines.append(f"| paper {v} | " + " | ".join(str(x) for x in PAPER[v][0]) + f" | {PAPER[v][1]} | | |")
    lines.append("")
    if any(pick(v, t) and "held_multiple" in pick(v, t) for v in VARIANTS for t in TASKS):
        grid = _grid_name([pick(v, t) for v in VARIANTS for t in TASKS])
        lines += [f"### Held task wrench: {hand}, {what}", "",
                  f"Per pose, the largest multiple of the task's disturbance held (bisection on the grid: {grid}; "
                  "0: none, or rejected before simulating); cells: median [p25, p75] over the poses (N in the table "
                  "above). Median held magnitude = median x the disturbance in the task table. Rows \"Ours vs "
                  "baseline\": the full method's median against the baseline's (same seeds per pose), and the "
                  "one-sided Mann-Whitney p of \"the full method's poses hold more\".", "",
                  "| variant | " + " | ".join(COLUMNS) + " |", "|---|" + "---|" * len(COLUMNS)]
        for v in TABLE_VARIANTS:
            cells = [pick(v, t) for t in TASKS]
            if any(c and "held_multiple" in c for c in cells):
                lines.append(f"| {VARIANTS[v][0]} | " + " | ".join(_held_cell(c) for c in cells) + " |")
        rows = [(pair, r) for pair in COMPARED if (r := _comparison_row(pick, pair))]
        lines += [row for _, (row, _) in rows]
        if rows:
            lines += [""] + [f"Held task wrench, {hand}, {what}, {pair[2].lower()}: {summary}."
                             for pair, (_, summary) in rows]
        lines.append("")
    lines += _energy_vs_test(pick, hand, what)
    if any(pick(v, t) and "success_stress" in pick(v, t) for v in VARIANTS for t in TASKS):
        lines += [f"### Robustness margin: {hand}, success % at 1x / 3x / 10x the disturbance (same poses)", "",
                  "| variant | " + " | ".join(COLUMNS) + " | average |", "|---|" + "---|" * (len(COLUMNS) + 1)]
        for v in ("baseline", "l2", "nocpn", "full"):
            cells = [pick(v, t) for t in TASKS]
            if not any(c and "success_stress" in c for c in cells):
                continue
            fmt = lambda c: "-" if not c or "success_stress" not in c else "/".join(  # noqa: E731
                _pct(x) for x in [c["success"]] + [c["success_stress"][str(k)] for k in STRESS])
            got = [c for c in cells if c and "success_stress" in c]
            avg = "/".join(f"{100 * np.mean([c['success'] if k == 1 else c['success_stress'][str(k)] for c in got]):.0f}"
                           for k in (1,) + STRESS)
            lines.append(f"| {VARIANTS[v][0]} | " + " | ".join(fmt(c) for c in cells) + f" | {avg} |")
        lines.append("")
    hyper = [v for v in ("full", "d15_k1e4", "d0_k1e2", "d0_k1e4") if any(pick(v, t) for t in TASKS)]
    if len(hyper) > 1:
        common = [t for t in TASKS if all(pick(v, t) for v in hyper)]
        lines += [f"## Hyper-parameters: {hand}, {what}", "",
                  f"Averages over the {len(common)} tasks every row has ({', '.join(common)}); time = synthesis "
                  "wall time per task at that row's size, memory = peak RSS above the (warm) process's RSS "
                  "before that synthesis.", "",
                  "| variant | delta | K | poses x iters | success % (tasks) | synthesis s per task (median) "
                  "| peak memory MB (max) | paper SS / t / M |", "|---|---|---|---|---|---|---|---|"]
        for v in hyper:
            cells = [pick(v, t) for t in common]
            cfg = dict(VARIANTS[v][1])
            sizes = sorted({f"{c['num']}x{c['iters']}" for c in cells})
            paper = PAPER_HYPER[v]
            lines.append(f"| {VARIANTS[v][0]} | {cfg.get('contact', {}).get('delta_deg', 15.0):g} | {cfg.get('num_directions', 100):.0e} | "
                         f"{', '.join(sizes)} | {100 * np.mean([c['success'] for c in cells]):.1f} ({len(cells)}) | "
                         f"{np.median([c['synth_s'] for c in cells]):.1f} | {max(c['peak_mb'] for c in cells):.0f} | "
                         f"{paper[0]} / {paper[1]} s / {paper[2]} GB |")
        lines.append("")
    lines.append("")
    return lines


def headline(records: Path, hand: str = "shadow", pair=("full", "baseline"), label: str = "tasks-generic") -> str:
    """``tasks-generic: full=F baseline=B ...``: ten-task averages, generic initialisation, latest
    code version that has both variants of ``pair`` on every task (with the poses per task)."""
    allrecs = _load(records)
    for version in sorted({r.get("code_version", "-") for r in allrecs},
                          key=lambda v: max(r["finished_at"] for r in allrecs if r.get("code_version", "-") == v),
                          reverse=True):
        recs = [r for r in allrecs if r.get("code_version", "-") == version]
        cells = {v: [_pick(recs, hand, v, t, "generic") for t in TASKS] for v in pair}
        if all(all(c) for c in cells.values()):
            f, b = (100 * np.mean([c["success"] for c in cells[v]]) for v in pair)
            n = "/".join(sorted({str(c["num"]) for v in cells for c in cells[v]}))
            cmp = _comparison_row(lambda v, t: _pick(recs, hand, v, t, "generic"), (*pair, label))
            held = f"; {cmp[1]}" if cmp else ""
            return f"{label}: full={f:.1f} baseline={b:.1f} (ten tasks, {hand}, N={n} poses per task, code {version}{held})"
    return f"{label}: full=- baseline=- (no complete generic-initialisation run of {hand} yet)"


def headline_s32(records: Path, hand: str = "shadow") -> str | None:
    """`headline` of the 32-seed pair (printed, not the report's last line), or None if not run."""
    line = headline(records, hand, ("full_s32", "baseline_s32"), "tasks-generic-32-seeds")
    return None if "=- " in line else line


NOTES_HEADING = "## Notes (hand-written"
RESULTS_HEADING = "# Results at code version "


def write_report(out: Path, text: str, last_line: str) -> None:
    """Write the generated report to ``out``, keeping the hand-written notes section (from
    ``NOTES_HEADING`` up to a final ``tasks-generic:`` line) of the file already there, and end
    it with ``last_line``."""
    old = out.read_text() if out.exists() else ""
    at = old.find(NOTES_HEADING)
    notes = old[at:].rstrip("\n") if at >= 0 else ""
    if notes.splitlines() and notes.splitlines()[-1].startswith("tasks-generic:"):
        if last_line.startswith("tasks-generic: full=- "):  # no generic records here: the old line stands
            last_line = notes.splitlines()[-1]
        notes = "\n".join(notes.splitlines()[:-1]).rstrip("\n")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text.rstrip("\n") + "\n" + ("\n" + notes + "\n" if notes else "") + "\n" + last_line + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tasks", default=",".join(TASKS), help="comma-separated task names")
    ap.add_argument("--variants", default="baseline,l2,nocpn,full,d0_k1e2,d15_k1e4,d0_k1e4")
    ap.add_argument("--hands", default="shadow", help="comma-separated; uninstalled hands are skipped")
    ap.add_argument("--num", type=int, default=100, help="poses per task and variant")
    ap.add_argument("--num-k1e4", type=int, default=None, help="poses for the K = 1e4 variants (default --num)")
    ap.add_argument("--iters", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--inits", default=",".join(INITS), help="initialisation regimes: task, generic")
    ap.add_argument("--no-self-penetration", default="", help="hands run with self-penetration weight 0 (LEAP did, until its self-collision got cheaper at da500f9)")
    ap.add_argument("--records", type=Path, default=RECORDS)
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--force", action="store_true", help="redo existing records")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args()
    from benchmarks.common import machine_description

    machine = machine_description()
    args.records.mkdir(parents=True, exist_ok=True)
    if not args.report_only:
        from datagen.hands import load_hand

        tasks, variants = args.tasks.split(","), args.variants.split(",")
        for v in variants:
            if v not in VARIANTS:
                raise SystemExit(f"unknown variant {v!r}; known: {list(VARIANTS)}")
        objects = Objects()
        for hname in args.hands.split(","):
            try:
                hand = load_hand(hname)
            except Exception as exc:  # noqa: BLE001 - an optional hand that is not installed
                print(f"skipping hand {hname}: {exc}", flush=True)
                continue
            for init in args.inits.split(","):
                for v in variants:
                    num = args.num_k1e4 if (args.num_k1e4 and "k1e4" in v) else args.num
                    for t in tasks:
                        path = record_path(args.records, hname, v, t, num, args.iters, init)
                        if path.exists() and not args.force:
                            continue
                        rec = run_record(hand, t, v, num, args.iters, objects, args.seed,
                                         hname in args.no_self_penetration.split(","), init)
                        path.write_text(json.dumps(rec, indent=1))
                        print(f"{hname} {init} {v} {t}: {100 * rec['success']:.0f}% held median "
                              f"{np.median(rec['held_multiple']):g} synth {rec['synth_s']:.1f}s eval "
                              f"{rec['eval_s']:.1f}s peak {rec['peak_mb']:.0f}MB {rec['reasons']}", flush=True)
                        write_report(args.out, render(args.records, machine), headline(args.records))
    line = headline(args.records)
    write_report(args.out, render(args.records, machine), line)
    print(f"wrote {args.out}")
    more = headline_s32(args.records)
    if more:
        print(more)
    print(line)


if __name__ == "__main__":
    main()
