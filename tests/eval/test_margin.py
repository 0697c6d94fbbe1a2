"""`Evaluator.margin`: the largest multiple of a task's disturbance a pose holds, checked against
a hand-computed case: the knob's hinge given a torsional spring (MuJoCo joint stiffness k, heavy
damping) and the hand parked 1 m away, so under a torque tau the knob settles at tau / k rad and
the test (pass below 10 deg) holds exactly the multiples m with m * 0.02 N m / k < 10 deg, on the
default quarter-octave grid and on the octave grid."""

import math

import numpy as np
import pytest

from datagen.eval import MULTIPLES, OCTAVE_MULTIPLES, EvalConfig, EvalError, Evaluator
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


CASES = [(OCTAVE_MULTIPLES, h) for h in (0.5, 4.0, 32.0)] + [(MULTIPLES, MULTIPLES[k]) for k in (4, 8, 18, 28)]


@pytest.mark.parametrize("grid,held", CASES, ids=[f"{len(g)}-{h:.3g}" for g, h in CASES])
def test_held_multiple_of_a_spring_loaded_knob_is_the_hand_computed_one(shadow, knob2, grid, held):
    base = EvalConfig().task_test("turn_knob2")
    assert base.torque_nm == 0.02 and base.max_rotation_deg == 10.0
    cfg = EvalConfig(tasks={"knob": dataclass_replace(base, min_touching_links=0)})
    limit = math.radians(10.0)
    i = grid.index(held)
    # the spring puts the threshold at the geometric middle between the expected multiple and
    # the grid's next one (x1.41 on octaves, x1.09 on quarter octaves)
    ratio = math.sqrt(grid[i + 1] / held) if i + 1 < len(grid) else 1.5
    k = 0.02 * ratio * held / limit  # N m / rad
    with Evaluator(shadow, cfg) as ev:
        scene, _ = ev.scene(knob2, cfg.task_test("knob"))
        j = scene.model.joint("object_joint").id
        scene.model.jnt_stiffness[j] = k
        scene.model.dof_damping[scene.model.jnt_dofadr[j]] = 0.1 * k  # overdamped, settles in ~0.1 s
        out = ev.margin(knob2, _parked(shadow), task="knob", multiples=grid)
        plain = ev.evaluate(knob2, _parked(shadow), task="knob")
    assert out.held_multiple == held
    assert out.held_wrench == pytest.approx(0.02 * held)
    assert out.result == plain  # the verdict at 1x is evaluate's
    assert out.result.success == (held >= 1)
    # bisection: 1 first, every tested multiple up to held holds, every one above fails, the
    # grid's neighbour above held was tested, in at most 1 + ceil(log2(side + 1)) simulations
    tested = dict(out.tested)
    assert out.tested[0] == (1.0, held >= 1)
    assert all(tested[m] for m in tested if m <= held) and all(not tested[m] for m in tested if m > held)
    if i + 1 < len(grid):
        assert tested[grid[i + 1]] is False
    one = grid.index(1.0)
    side = len(grid) - one - 1 if held >= 1 else one
    assert len(out.tested) <= 1 + math.ceil(math.log2(side + 1))
    # a held 1x test reports the settled angle tau / k as its worst pose error
    if held >= 1:
        assert out.result.direction_rotation_deg[0] == pytest.approx(math.degrees(0.02 / k), rel=0.05)


def test_default_grid_is_quarter_octaves_from_a_quarter_to_32():
    assert MULTIPLES[0] == 0.25 and MULTIPLES[-1] == 32.0 and 1.0 in MULTIPLES
    assert np.allclose(np.diff(np.log2(MULTIPLES)), 0.25)
    assert set(OCTAVE_MULTIPLES) <= {round(m, 12) for m in MULTIPLES}


def test_rejected_pose_holds_nothing_and_bad_grid_is_named(shadow, knob2):
    with Evaluator(shadow, EvalConfig()) as ev:
        out = ev.margin(knob2, _parked(shadow), task="turn_knob2")
        assert out.result.reason == "no_contact" and out.held_multiple == 0 and out.tested == ()
        with pytest.raises(EvalError, match="multiples"):
            ev.margin(knob2, _parked(shadow), task="turn_knob2", multiples=(2.0, 4.0))


def dataclass_replace(obj, **kw):
    import dataclasses

    return dataclasses.replace(obj, **kw)
