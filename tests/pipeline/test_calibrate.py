"""`datagen hand calibrate`: the paired choice (hand-worked outcome vectors) and the search on a
tiny case against candidates constructed to be worse."""

from __future__ import annotations

import math

import pytest

from datagen.pipeline.calibrate import MAX_PENETRATION_P90_M, Candidate, _better

from .test_batch import world  # noqa: F401 - the processed box (a fixture)


def c(outcomes: str, p90_mm: float = 0.3) -> Candidate:
    """A candidate from its per-grasp outcomes, '1' a hold."""
    return Candidate((("sphere_margin_m", 0.0008),), tuple(ch == "1" for ch in outcomes), p90_mm / 1000, 1.0)


def test_a_challenger_must_win_clearly_more_pairs_than_it_loses():
    base = c("0000000000" "1111111111")
    assert _better(c("1111110000" "1111111111"), base)                 # 6 wins, 0 losses: 6 >= 2 sqrt(6)
    assert not _better(c("1111100000" "1111111110"), base)             # 5 wins, 1 loss: 4 < 2 sqrt(6)
    assert not _better(c("1100000000" "1111111111"), base)             # 2 wins: 2 < 2 sqrt(2)
    assert not _better(c("0000000000" "1111111111"), base)             # a tie keeps the incumbent
    # the same totals in other pairs: 10 wins, 10 losses, no lead
    assert not _better(c("1111111111" "0000000000"), base)


def test_the_penetration_bound_comes_first():
    base = c("0000000000" "1111111111")
    assert not _better(c("1111111111" "1111111111", p90_mm=1.1), base)   # holds all, penetrates too deep
    deep = c("1111111111" "1111111111", p90_mm=1.3)
    assert _better(c("0000000001", p90_mm=0.5), deep)                    # any within the bound replaces it
    assert _better(c("0000000001", p90_mm=1.0), deep)                    # over it too, but less deep
    assert not _better(c("0000000000", p90_mm=math.nan), deep)           # no success: nothing measured
    assert 0.0005 < MAX_PENETRATION_P90_M < 0.001


@pytest.fixture
def tiny_calibration(world, tmp_path, monkeypatch):  # noqa: F811
    """``run(start_margin_m, tried)``: calibrate a renamed copy of the Shadow spec (its rows' hand
    is then loaded from where the calibration pins it) whose margin is ``start_margin_m`` on one
    box at 0.06 and 0.08 m, 4 grasps each, a short synthesis, trying only ``tried``."""
    import yaml

    import datagen.pipeline.calibrate as cal
    from datagen.hands import builtin_spec_path
    from datagen.pipeline import BatchObject

    done, cache, _ = world
    box = done["box.obj"]
    monkeypatch.setattr(cal, "_objects", lambda count, process, cache, log: [
        BatchObject(box, (0.06, 0.08), object_id="box", object_path=str(box.entry))])
    tiny = {"synth": {"iters": 60, "seeds_per_grasp": 1, "seed_select_iter": 30}, "grid_resolution": 16}

    def run(start_margin_m: float, tried: tuple[float, ...]):
        data = yaml.safe_load(builtin_spec_path("shadow").read_text())
        data.update(name="my_shadow", sphere_margin_m=start_margin_m)
        spec = tmp_path / "my_shadow.yaml"
        spec.write_text(yaml.safe_dump(data))
        result = cal.calibrate_spec(spec, objects=1, grasps=4, cache=cache, config=tiny,
                                    fields={"sphere_margin_m": lambda v: tried})
        return spec, result

    return run


def test_calibrate_keeps_the_start_against_a_worse_candidate(tiny_calibration):
    """A 6 mm margin sinks the spheres past the pads' 2.8 mm overshoot: the real fingers go into
    the box, which MuJoCo measures (no hold, or successes deeper than the bound); calibration
    keeps the derived-range start, and writes it with every candidate's figures."""
    from datagen.hands import load_spec

    spec, result = tiny_calibration(0.0008, (0.006,))
    start, worse = result.candidates
    assert start.grasps == worse.grasps == 8 and start.successes > 0
    assert worse.successes < start.successes or worse.penetration_p90_m > MAX_PENETRATION_P90_M
    assert result.chosen is start and load_spec(spec).sphere_margin_m == 0.0008
    text = spec.read_text()
    assert "calibrated by `datagen hand calibrate`" in text and "6.00 mm" in text
    spec2, result2 = tiny_calibration(0.0008, (0.006,))  # the same seed: the same figures, the same file
    assert [c.outcomes for c in result2.candidates] == [c.outcomes for c in result.candidates]
    assert spec2.read_text() == text


def test_calibrate_leaves_a_worse_start_for_the_better_candidate(tiny_calibration):
    """The same pair the other way round: starting from 6 mm, calibration moves to 0.8 mm."""
    from datagen.hands import load_spec

    spec, result = tiny_calibration(0.006, (0.0008,))
    worse, better = result.candidates
    assert better.successes > 0 and better.penetration_p90_m <= MAX_PENETRATION_P90_M
    assert result.chosen is better and load_spec(spec).sphere_margin_m == 0.0008


def test_the_calibration_sees_every_grasp_type_of_the_default_job():
    """The default job's objects (manifests/real_dev.jsonl's scales) get fingertip grasps up to
    0.09 m and power grasps above (the dataset preset's bands): the calibration's scales give
    both, so a margin whose power grasps press in (the D'Claw's phalanges) is measured too."""
    import json
    from pathlib import Path

    from datagen.pipeline import resolve
    from datagen.pipeline.calibrate import CALIBRATION_SCALES

    mix = resolve("shadow", "force_closure").grasp_types
    manifest = Path(__file__).resolve().parents[2] / "manifests" / "real_dev.jsonl"
    job = {s for line in manifest.read_text().splitlines() if line.strip() for s in json.loads(line)["scales"]}

    def types(scales):
        return {t for s in scales for t in mix.counts(s, 10)}

    assert types(job) == {"precision", "power"} and types(CALIBRATION_SCALES) == types(job)
