"""`datagen hand calibrate`'s choice among candidate margins (hand-worked cases)."""

from __future__ import annotations

import math

from datagen.pipeline.calibrate import Candidate, _choose

from .test_batch import world  # noqa: F401 - the processed box (a fixture)


def c(margin_mm: float, ok: int, p90_mm: float) -> Candidate:
    return Candidate(margin_mm / 1000, 32, ok, p90_mm / 1000, 1.0)


def test_most_successes_within_the_penetration_bound():
    cands = [c(0.4, 20, 0.3), c(0.8, 24, 0.6), c(1.2, 28, 1.1)]  # 1.2 mm holds more but penetrates 1.1 mm
    assert _choose(cands, 0.0008).margin_m == 0.0008


def test_ties_go_to_the_derived_margin_then_the_smaller():
    assert _choose([c(0.4, 24, 0.3), c(0.8, 24, 0.6), c(1.2, 24, 0.7)], 0.0008).margin_m == 0.0008
    assert _choose([c(0.4, 24, 0.3), c(0.8, 20, 0.6), c(1.2, 24, 0.7)], 0.0008).margin_m == 0.0004


def test_when_none_qualifies_the_least_penetrating():
    cands = [c(0.4, 0, math.nan), c(0.8, 10, 1.3), c(1.2, 12, 1.6)]
    assert _choose(cands, 0.0008).margin_m == 0.0008


def test_calibrate_runs_each_candidate_and_writes_the_choice(world, tmp_path, monkeypatch):
    """A copy of the Shadow spec under another name (the rows' hand is then loaded from where the
    calibration pins it), one box, a few iterations: every candidate yields rows, the spec gets
    the chosen margin and a comment with every candidate's figures."""
    import yaml

    import datagen.pipeline.calibrate as cal
    from datagen.hands import builtin_spec_path, load_spec
    from datagen.pipeline import BatchObject

    done, cache, _ = world
    data = yaml.safe_load(builtin_spec_path("shadow").read_text())
    data["name"] = "my_shadow"
    spec = tmp_path / "my_shadow.yaml"
    spec.write_text(yaml.safe_dump(data))
    box = done["box.obj"]
    monkeypatch.setattr(cal, "_objects", lambda count, process, cache, log: [
        BatchObject(box, (0.08,), object_id="box", object_path=str(box.entry))])
    tiny = {"synth": {"iters": 8, "seeds_per_grasp": 1}, "grid_resolution": 16}
    result = cal.calibrate_spec(spec, objects=1, grasps=1, cache=cache, config=tiny)
    assert [c.grasps for c in result.candidates] == [1, 1, 1]
    margins = [c.margin_m for c in result.candidates]
    assert load_spec(spec).sphere_margin_m == result.chosen.margin_m and result.chosen.margin_m in margins
    assert "calibrated by `datagen hand calibrate`" in spec.read_text()
