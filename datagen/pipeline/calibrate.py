"""``datagen hand calibrate``: choose a hand's sphere margin by a short run of the product itself.

The margin (`HandSpec.sphere_margin_m`: how far synthesis lets the collision spheres sink into an
object) trades success against penetration, and for the built-in hands it was tuned by hand from
MuJoCo runs (Shadow 1.5 mm, Allegro and LEAP 0.5 mm). Here the candidates are the value derived
from the hand's geometry (`datagen.hands.derive`), a smaller and a larger one; each runs the
default force-closure synthesis (the job's: 300 iterations, the best of 16 starts) and the
unchanged six-direction MuJoCo test on a few procedural objects (never the real-object set the
results are reported on). The choice: the most successes among the candidates whose successful
grasps penetrate at most `MAX_PENETRATION_P90_M` at the 90th percentile, ties to the derived
value, then to the smaller margin; when none qualifies, the least penetrating. Same seed, same
choice.
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

__all__ = ["CALIBRATION_SCALES", "Candidate", "Calibration", "MAX_PENETRATION_P90_M", "calibrate_spec",
           "format_calibration"]

CALIBRATION_SCALES = (0.06, 0.08)       # the default job's scales
MAX_PENETRATION_P90_M = 0.0008          # below the 1 mm the results are held to, for the real objects' spread
_SPREAD_M = 0.0004                      # the neighbours of the derived margin


@dataclass(frozen=True)
class Candidate:
    margin_m: float
    grasps: int
    successes: int
    penetration_p90_m: float            # over the successful grasps (nan without any)
    seconds: float

    @property
    def ok(self) -> bool:
        return self.successes > 0 and self.penetration_p90_m <= MAX_PENETRATION_P90_M


@dataclass(frozen=True)
class Calibration:
    spec: Path                          # the spec written
    derived_m: float
    chosen: Candidate
    candidates: tuple[Candidate, ...]
    objects: tuple[str, ...]


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


def _run(hand, objects, recipe, margin: float, grasps: int, seed: int, cache, base: Path) -> Candidate:
    from .batch import run_batch

    t0 = time.perf_counter()
    recipe = dataclasses.replace(recipe, synth=dataclasses.replace(recipe.synth, sphere_margin_m=margin))
    out = run_batch(objects, hand, [recipe], grasps_per_object=grasps, seed=seed, cache=cache, base=base)
    rows = out.rows
    if rows.num_rows == 0:
        first = out.failures[0] if out.failures else {}
        raise ValueError(f"calibration of hand {hand.name!r}: no grasp rows at margin {margin * 1000:.2f} mm "
                         f"({len(out.failures)} failures; first: {first.get('stage')}: {first.get('message')})")
    ok = np.asarray(rows.column("success").to_pylist(), dtype=bool)
    pen = np.asarray(rows.column("penetration_m").to_pylist(), dtype=float)
    p90 = float(np.percentile(pen[ok], 90)) if ok.any() else float("nan")
    return Candidate(round(margin, 6), int(len(ok)), int(ok.sum()), p90, time.perf_counter() - t0)


def _choose(candidates: list[Candidate], derived: float) -> Candidate:
    good = [c for c in candidates if c.ok]
    if not good:
        return min(candidates, key=lambda c: (np.nan_to_num(c.penetration_p90_m, nan=1.0), c.margin_m))
    return max(good, key=lambda c: (c.successes, c.margin_m == derived, -c.margin_m))


def calibrate_spec(spec_path: str | Path, *, out: str | Path | None = None, objects: int = 4, grasps: int = 4,
                   seed: int = 0, cache: str | None = None, config: Mapping | None = None,
                   log: Callable[[str], None] = lambda _: None) -> Calibration:
    """Run the candidates on ``objects`` procedural objects (``grasps`` per object and scale each)
    with the default job's force-closure recipe (``config``: settings on top, as a job's config
    file gives them; `datagen.pipeline.resolve`) and write the spec with the chosen margin to
    ``out`` (default: ``spec_path`` itself)."""
    from .recipe import resolve

    from datagen.hands import load_hand, load_spec, pin_hand
    from datagen.hands.derive import MARGIN_RANGE_M, derive_settings
    from datagen.hands.mjcf import flatten_hand, resolve_asset
    from datagen.hands.spec import dump_spec

    if objects < 1 or grasps < 1:
        raise ValueError(f"--objects and --grasps must be >= 1, got {objects}, {grasps}")
    spec_path = Path(spec_path)
    spec = load_spec(spec_path)
    hand = load_hand(spec_path)
    flat = flatten_hand(resolve_asset(spec.mjcf, spec.source_file), spec.root_body, name=spec.name,
                        position_kp=spec.position_actuator_kp)
    derived = float(derive_settings(spec, flat).values["sphere_margin_m"])
    lo, hi = MARGIN_RANGE_M
    margins = sorted({round(float(np.clip(m, lo, hi)), 6) for m in (derived - _SPREAD_M, derived, derived + _SPREAD_M)})
    recipe = resolve(str(spec_path), "force_closure", config=config)
    objs = _objects(objects, recipe.process, cache, log)
    # the evaluation loads the hand again by the rows' name: from a folder where it is pinned
    base = Path(tempfile.mkdtemp(prefix="datagen-calibrate-"))
    pin_hand(spec, base)
    log(f"calibrating {spec.name!r}: sphere margins {[round(m * 1000, 2) for m in margins]} mm on "
        f"{len(objs)} procedural objects x {len(CALIBRATION_SCALES)} scales x {grasps} grasps")
    results = []
    try:
        for m in margins:
            c = _run(hand, objs, recipe, m, grasps, seed, cache, base)
            log(f"  margin {m * 1000:.2f} mm: {c.successes}/{c.grasps} hold, penetration p90 "
                f"{c.penetration_p90_m * 1000:.2f} mm ({c.seconds:.0f} s)")
            results.append(c)
    finally:
        shutil.rmtree(base, ignore_errors=True)
    chosen = _choose(results, round(derived, 6))
    target = Path(out) if out else spec_path
    header = _leading_comments(spec_path) + [
        f"sphere_margin_m calibrated by `datagen hand calibrate` (seed {seed}): "
        + ", ".join(f"{c.margin_m * 1000:.2f} mm {c.successes}/{c.grasps} pen p90 {c.penetration_p90_m * 1000:.2f} mm"
                    for c in results) + f"; chose {chosen.margin_m * 1000:.2f} mm"]
    dump_spec(dataclasses.replace(spec, sphere_margin_m=chosen.margin_m), target, "\n".join(header))
    return Calibration(target, derived, chosen, tuple(results), tuple(o.object_id for o in objs))


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
    return (f"wrote {cal.spec}: sphere_margin_m = {c.margin_m} ({c.successes}/{c.grasps} six-direction holds, "
            f"penetration p90 {c.penetration_p90_m * 1000:.2f} mm on {len(cal.objects)} procedural objects; "
            f"derived from the geometry: {cal.derived_m})")
