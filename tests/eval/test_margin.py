"""`Evaluator.margin`: the largest multiple of a task's disturbance a pose holds, checked against
a hand-computed case: the knob's hinge given a torsional spring (MuJoCo joint stiffness k, heavy
damping) and the hand parked 1 m away, so under a torque tau the knob settles at tau / k rad and
the test (pass below 10 deg) holds exactly the multiples m with m * 0.02 N m / k < 10 deg."""

import math

import numpy as np
import pytest

from datagen.eval import MULTIPLES, EvalConfig, EvalError, Evaluator
from datagen.eval.scene import pieces_from_processed
from datagen.objects import task_objects as T
from datagen.objects.process import process_object
from datagen.objects.sources import resolve


@pytest.fixture(scope="module")
def knob2(tmp_path_factory):
    ref = resolve("tasks", "knob2", T.object_id("knob2"))
    p = process_object(ref, root=tmp_path_factory.mktemp("knob2"))
    return pieces_from_processed(p, T.build("knob2").scale_m)


def _parked(hand) -> np.ndarray:
    """(3, 7 + J): the open hand 1 m above the object, pregrasp = grasp = squeeze."""
    row = np.concatenate([[0, 0, 1.0, 1, 0, 0, 0], hand.open_pose.double().numpy()])
    return np.stack([row, row, row])


@pytest.mark.parametrize("held", [0.5, 4.0, 32.0])
def test_held_multiple_of_a_spring_loaded_knob_is_the_hand_computed_one(shadow, knob2, held):
    base = EvalConfig().task_test("turn_knob2")
    assert base.torque_nm == 0.02 and base.max_rotation_deg == 10.0
    cfg = EvalConfig(tasks={"knob": dataclass_replace(base, min_touching_links=0)})
    limit = math.radians(10.0)
    # the spring puts the threshold 1.5x above the expected multiple: that multiple settles at
    # 2/3 of the limit, the next grid one (2x) at 4/3 of it
    k = 0.02 * 1.5 * held / limit  # N m / rad
    with Evaluator(shadow, cfg) as ev:
        scene, _ = ev.scene(knob2, cfg.task_test("knob"))
        j = scene.model.joint("object_joint").id
        scene.model.jnt_stiffness[j] = k
        scene.model.dof_damping[scene.model.jnt_dofadr[j]] = 0.05  # overdamped: no overshoot
        out = ev.margin(knob2, _parked(shadow), task="knob")
        plain = ev.evaluate(knob2, _parked(shadow), task="knob")
    assert out.held_multiple == held
    assert out.held_wrench == pytest.approx(0.02 * held)
    assert out.result == plain  # the verdict at 1x is evaluate's
    assert out.result.success == (held >= 1)
    # the scan: up from 1 while it holds (the last one fails unless the grid ends), down from 1 otherwise
    tested = dict(out.tested)
    assert all(tested[m] for m in tested if m <= held) and all(not tested[m] for m in tested if m > held)
    if held < MULTIPLES[-1]:
        assert 2 * held in tested
    # a held 1x test reports the settled angle tau / k as its worst pose error
    if held >= 1:
        assert out.result.direction_rotation_deg[0] == pytest.approx(math.degrees(0.02 / k), rel=0.05)


def test_rejected_pose_holds_nothing_and_bad_grid_is_named(shadow, knob2):
    with Evaluator(shadow, EvalConfig()) as ev:
        out = ev.margin(knob2, _parked(shadow), task="turn_knob2")
        assert out.result.reason == "no_contact" and out.held_multiple == 0 and out.tested == ()
        with pytest.raises(EvalError, match="multiples"):
            ev.margin(knob2, _parked(shadow), task="turn_knob2", multiples=(2.0, 4.0))


def dataclass_replace(obj, **kw):
    import dataclasses

    return dataclasses.replace(obj, **kw)
