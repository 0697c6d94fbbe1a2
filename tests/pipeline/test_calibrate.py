"""`datagen hand calibrate`'s choice among candidate margins (hand-worked cases)."""

from __future__ import annotations

import math

from datagen.pipeline.calibrate import Candidate, _choose


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
