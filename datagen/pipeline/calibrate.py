"""``datagen hand calibrate``: choose a hand's free values by a short, paired run of the product.

What a new hand's spec cannot derive from its geometry (`datagen.hands.derive`) is chosen here by
measurement: each candidate setting runs the default force-closure synthesis, made cheaper
(`CHEAP_SYNTH`: fewer iterations and starts than a job's), and the unchanged six-direction MuJoCo
test on a few procedural objects (never the real-object set results are reported on). Every
candidate runs on the same targets with the same seed, so the same initial poses: grasp k of one
candidate and grasp k of another differ only by the setting, and they are compared pair by pair
(`_better`: a challenger replaces the incumbent only when it wins clearly more pairs than it
loses, `MIN_LEAD` and two standard deviations of a fair coin; its successes must not penetrate
more than `MAX_PENETRATION_P90_M` at the 90th percentile). Ties keep the incumbent, which starts
as the derived value: without evidence nothing moves.

Searched (`SEARCH`): the sphere margin (`HandSpec.sphere_margin_m`: how far synthesis lets the
collision spheres sink into an object), from the derived value 0.4 mm either way, one field at
a time (coordinate search from the incumbent). The choice and every candidate's figures are
written into the spec. Same seed, same choice. The squeeze force and gap, the initial palm
distance and a curled pre-shape were measured with `Bench` too and moved nothing clearly
(benchmarks/results/hands.md), so they are not searched.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

__all__ = ["CALIBRATION_SCALES", "CHEAP_SYNTH", "Candidate", "Calibration", "MAX_PENETRATION_P90_M", "MIN_LEAD",
           "SEARCH", "Bench", "calibrate_spec", "format_calibration", "search"]

# the default job's scales (manifests/real_dev.jsonl's), 0.10 m included: the dataset preset gives
# it power grasps, whose phalanges press in where fingertips do not (D'Claw: with 0.06/0.08 m only,
# the derived 0.9 mm stayed and the gate's power grasps penetrated 1.30 mm at p90)
CALIBRATION_SCALES = (0.06, 0.08, 0.10)
# synthesis of the calibration run: the job's schedule (its seed choice at 120 iterations) cut
# short, a quarter of its starts (the job: 300 iterations, 16 starts)
CHEAP_SYNTH = {"iters": 200, "seeds_per_grasp": 4}
MAX_PENETRATION_P90_M = 0.0008          # below the 1 mm the results are held to, for the real objects' spread
MIN_LEAD = 2                            # a challenger must win at least this many more pairs than it loses
# field -> the candidate values tried around the incumbent's value v (spec fields that are also
# SynthConfig fields); the margin within the range it is derived in (derive.MARGIN_RANGE_M)
SEARCH: dict[str, Callable[[float], tuple[float, ...]]] = {
    "sphere_margin_m": lambda v: tuple(np.clip((v - 0.0004, v + 0.0004), 0.0003, 0.0015)),
}


@dataclass(frozen=True)
class Candidate:
    settings: tuple[tuple[str, float], ...]   # (spec field, value), the bench's whole setting
    outcomes: tuple[bool, ...]                # six-direction success per grasp, in the bench's order
    penetration_p90_m: float                  # over the successful grasps (nan without any)
    seconds: float

    @property
    def grasps(self) -> int:
        return len(self.outcomes)

    @property
    def successes(self) -> int:
        return int(sum(self.outcomes))

    @property
    def ok(self) -> bool:
        """Its successes penetrate at most `MAX_PENETRATION_P90_M` (p90)."""
        return self.successes > 0 and self.penetration_p90_m <= MAX_PENETRATION_P90_M

    def value(self, field: str) -> float:
        return dict(self.settings)[field]

    def line(self, seconds: bool = True) -> str:
        """One line of figures (``seconds``: with its run time; the spec's comment has none, so the
        same seed writes the same file)."""
        s = ", ".join(f"{k} {v * 1000:.2f} mm" if k.endswith("_m") else f"{k} {v:g}" for k, v in self.settings)
        return (f"{s}: {self.successes}/{self.grasps} hold, penetration p90 {self.penetration_p90_m * 1000:.2f} mm"
                + (f" ({self.seconds:.0f} s)" if seconds else ""))


@dataclass(frozen=True)
class Calibration:
    spec: Path                                # the spec written
    derived: tuple[tuple[str, float], ...]    # the starting values (derived from the geometry)
    chosen: Candidate
    candidates: tuple[Candidate, ...]         # in the order they ran
    objects: tuple[str, ...]


def _better(challenger: Candidate, incumbent: Candidate) -> bool:
    """Whether ``challenger`` replaces ``incumbent`` (same bench, so grasp k of one pairs with
    grasp k of the other): within the penetration bound, and winning at least `MIN_LEAD` and two
    standard deviations (of a fair coin over the discordant pairs) more pairs than it loses. An
    incumbent over the bound is replaced by any challenger that penetrates less."""
    if not incumbent.ok:
        pen = lambda c: np.nan_to_num(c.penetration_p90_m, nan=1.0) if c.successes else 1.0  # noqa: E731
        return challenger.ok or pen(challenger) < pen(incumbent)
    if not challenger.ok:
        return False
    a, b = np.asarray(challenger.outcomes), np.asarray(incumbent.outcomes)
    wins, losses = int((a & ~b).sum()), int((~a & b).sum())
    return wins - losses >= max(MIN_LEAD, 2.0 * math.sqrt(wins + losses))


class Bench:
    """Candidate settings of one hand on fixed targets: ``run(settings)`` synthesizes
    ``grasps`` per target with ``recipe`` (its synth fields replaced by ``settings``) and the
    same ``seed`` every time, and evaluates them (the unchanged test of ``recipe.eval``)."""

    def __init__(self, hand, recipe, targets: Sequence, grasps: int, seed: int, base: Path):
        self.hand, self.recipe, self.targets, self.grasps, self.seed, self.base = (
            hand, recipe, list(targets), grasps, seed, base)

    def run(self, settings: Mapping[str, float]) -> Candidate:
        from .batch import evaluate_rows, synthesize_rows

        t0 = time.perf_counter()
        task = self.recipe.load_task()
        cfg = dataclasses.replace(self.recipe.synth, seed=self.seed, **dict(settings))
        types = {t: {k: v for k, v in o.items() if k not in settings}  # the candidate's settings win
                 for t, o in self.recipe.grasp_type_synth.items()}
        _, table = synthesize_rows(self.hand, self.targets, task, cfg, self.grasps,
                                   grasp_types=self.recipe.grasp_types, type_synth=types)
        fails: list = []
        tables = evaluate_rows(table, self.targets, task.name, self.recipe.eval, base=self.base, failures=fails)
        if fails:
            raise ValueError(f"calibration of hand {self.hand.name!r} at {dict(settings)}: the evaluation "
                             f"failed: {fails[0]['message']}")
        ok = np.concatenate([np.asarray(t.column("success").to_pylist(), dtype=bool) for t in tables])
        pen = np.concatenate([np.asarray(t.column("penetration_m").to_pylist(), dtype=float) for t in tables])
        p90 = float(np.percentile(pen[ok], 90)) if ok.any() else float("nan")
        return Candidate(tuple(sorted((k, round(float(v), 6)) for k, v in settings.items())),
                         tuple(bool(x) for x in ok), p90, time.perf_counter() - t0)


def search(bench: Bench, start: Mapping[str, float], log: Callable[[str], None] = lambda _: None,
           fields: Mapping[str, Callable[[float], tuple[float, ...]]] | None = None) -> tuple[Candidate, list]:
    """``(chosen, every candidate run)``: from ``start``, each field of ``fields`` (default
    `SEARCH`) in turn, its candidate values around the incumbent's, the incumbent replaced by a
    `_better` one."""
    fields = SEARCH if fields is None else fields
    incumbent = bench.run(start)
    log(f"  {incumbent.line()} (start)")
    runs = [incumbent]
    for name, around in fields.items():
        base = incumbent
        for v in sorted({round(float(x), 6) for x in around(base.value(name))} - {base.value(name)}):
            c = bench.run({**dict(base.settings), name: v})
            runs.append(c)
            if _better(c, incumbent):
                incumbent = c
            log(f"  {c.line()}" + (" (best so far)" if incumbent is c else ""))
    return incumbent, runs


def _objects(count: int, process, cache, log) -> list:
    from datagen.objects.isolate import process_isolated
    from datagen.objects.manifest import build_manifest, resolve_scales
    from datagen.objects.process import load_processed

    from .batch import BatchObject

    out = []
    for e in build_manifest("procedural", count, CALIBRATION_SCALES, test_fraction=0.0):
        p = process_isolated(e, process, cache, 300.0)
        if not p.ok:
            log(f"calibration object {e.id} skipped: {p.reason}")
            continue
        processed = load_processed(p.entry)
        out.append(BatchObject(processed, resolve_scales(e.scales, processed.factor, e.id), object_id=e.id,
                               object_path=str(p.entry)))
    if not out:
        raise ValueError("no procedural calibration object could be processed (see the lines above)")
    return out


def calibrate_spec(spec_path: str | Path, *, out: str | Path | None = None, objects: int = 6, grasps: int = 3,
                   seed: int = 0, cache: str | None = None, config: Mapping | None = None,
                   fields: Mapping[str, Callable[[float], tuple[float, ...]]] | None = None,
                   log: Callable[[str], None] = lambda _: None) -> Calibration:
    """Search ``fields`` (default `SEARCH`) on ``objects`` procedural objects x
    `CALIBRATION_SCALES` x ``grasps`` with the default job's force-closure recipe made cheap
    (`CHEAP_SYNTH`; ``config``: settings on top, as a job's config file gives them;
    `datagen.pipeline.resolve`), starting from the spec's values, and write the spec with the
    choice to ``out`` (default: ``spec_path`` itself)."""
    import torch

    from .batch import build_targets
    from .recipe import merge_layers, resolve

    from datagen.hands import load_hand, load_spec, pin_hand
    from datagen.hands.spec import dump_spec

    if objects < 1 or grasps < 1:
        raise ValueError(f"--objects and --grasps must be >= 1, got {objects}, {grasps}")
    spec_path = Path(spec_path)
    spec = load_spec(spec_path)
    hand = load_hand(spec_path)
    fields = SEARCH if fields is None else fields
    start = {k: float(getattr(spec, k)) for k in fields}
    recipe = resolve(str(spec_path), "force_closure", config=merge_layers({"synth": CHEAP_SYNTH}, config or {}))
    objs = _objects(objects, recipe.process, cache, log)
    targets = build_targets(objs, grid_resolution=recipe.grid_resolution, cache=cache)
    # the evaluation loads the hand again by the rows' name: from a folder where it is pinned
    base = Path(tempfile.mkdtemp(prefix="datagen-calibrate-"))
    pin_hand(spec, base)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as a job's shard (one CPU each): the same poses, and no oversubscription
    log(f"calibrating {spec.name!r} ({', '.join(fields)}) on {len(objs)} procedural objects x "
        f"{len(CALIBRATION_SCALES)} scales x {grasps} grasps, {recipe.synth.iters} iterations, "
        f"{recipe.synth.seeds_per_grasp} starts, seed {seed}")
    try:
        chosen, runs = search(Bench(hand, recipe, targets, grasps, seed, base), start, log, fields)
    finally:
        torch.set_num_threads(threads)
        shutil.rmtree(base, ignore_errors=True)
    target = Path(out) if out else spec_path
    header = _leading_comments(spec_path) + [
        f"calibrated by `datagen hand calibrate` (seed {seed}, {len(objs)} procedural objects, "
        f"{len(targets) * grasps} paired grasps per candidate): " + "; ".join(c.line(False) for c in runs)
        + "; chose " + ", ".join(f"{k} = {v}" for k, v in chosen.settings)]
    dump_spec(dataclasses.replace(spec, **dict(chosen.settings)), target, "\n".join(header))
    return Calibration(target, tuple(sorted(start.items())), chosen, tuple(runs), tuple(o.object_id for o in objs))


def _leading_comments(path: Path) -> list[str]:
    out = []
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        if "calibrated by `datagen hand calibrate`" not in line:
            out.append(line[2:] if line.startswith("# ") else line[1:])
    return out


def format_calibration(cal: Calibration) -> str:
    c = cal.chosen
    start = dict(cal.derived)
    moved = ", ".join(f"{k} = {v} (was {start[k]})" if v != start[k] else f"{k} = {v} (unchanged)"
                      for k, v in c.settings)
    return (f"wrote {cal.spec}: {moved}; {c.successes}/{c.grasps} six-direction holds, penetration p90 "
            f"{c.penetration_p90_m * 1000:.2f} mm on {len(cal.objects)} procedural objects "
            f"({len(cal.candidates)} candidates, {sum(x.seconds for x in cal.candidates):.0f} s)")
