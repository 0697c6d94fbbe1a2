"""The tabletop test on a grasp built with MuJoCo: a wide box held against the palm, the table
under its face away from the thumb. The table sits where the row's plane says and holds the object
up against the gravity-equivalent force; the held box lifts off it; a hand lowered into the table
is hand_in_table, one millimetre of depth per millimetre; the lift's failures get their codes."""

import mujoco
import numpy as np
import pytest

from datagen.eval import EvalConfig, Evaluator
from datagen.eval.lift import LiftResult, lift_reason, table_depth
from datagen.eval.hold import DirectionResult

from .grasps import box_grasp

pytestmark = pytest.mark.mujoco

HALF = (0.075, 0.015, 0.03)  # m: wider than the hand, so the table at its -x face clears the fingers
PLANE = (1.0, 0.0, 0.0, HALF[0])  # the table's up direction +x: its surface at x = -7.5 cm


@pytest.fixture(scope="module")
def evaluator(shadow):
    with Evaluator(shadow, EvalConfig()) as ev:
        yield ev


@pytest.fixture(scope="module")
def held(evaluator, box_dir):
    return box_grasp(evaluator, HALF, drop=0.0, directory=box_dir)


def test_the_table_is_the_rows_plane_and_holds_the_object_up(shadow, evaluator, held):
    pieces, _ = held
    scene, _ = evaluator.scene(pieces, None, PLANE)
    m = scene.model
    (g,) = scene.table_geoms
    assert m.geom_type[g] == int(mujoco.mjtGeom.mjGEOM_PLANE)
    assert np.allclose(m.geom_pos[g], [-HALF[0], 0, 0])
    z = np.zeros(3)
    mujoco.mju_rotVecQuat(z, np.array([0, 0, 1.0]), m.geom_quat[g])
    assert np.allclose(z, PLANE[:3])
    # the hand parked 1 m away, 1 N pushing the box onto the table for 1 s: it stays put (< 1 mm) ...
    d = mujoco.MjData(m)
    d.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = d.mocap_pos[scene.mocap] = [0, 0, 1.0]
    d.xfrc_applied[scene.object_body, :3] = -1.0 * np.asarray(PLANE[:3])
    mujoco.mj_step(m, d, nstep=250)
    assert np.linalg.norm(d.xpos[scene.object_body]) < 1e-3
    # ... and without the table it is pushed through where the table was
    free, _ = evaluator.scene(pieces)
    d = mujoco.MjData(free.model)
    d.qpos[free.hand_free_qpos:free.hand_free_qpos + 3] = d.mocap_pos[free.mocap] = [0, 0, 1.0]
    d.xfrc_applied[free.object_body, :3] = -1.0 * np.asarray(PLANE[:3])
    mujoco.mj_step(free.model, d, nstep=250)
    assert d.xpos[free.object_body][0] < -0.05


def test_held_box_lifts_off_the_table(evaluator, held):
    pieces, poses = held
    r = evaluator.evaluate(pieces, poses, table=PLANE)
    assert r.success and r.reason == "ok" and r.test == "tabletop_lift"
    assert r.direction_success == (True,) and r.direction_translation_m[0] < 0.05 and r.direction_rotation_deg[0] < 15
    assert r.table_penetration_m == 0.0 and r.sim_steps == 3 * 10 * 10
    assert evaluator.evaluate(pieces, poses).test == "six_direction"  # no table: the floating test, as before


def test_a_heavy_box_stays_on_the_table(shadow, held):
    pieces, poses = held
    with Evaluator(shadow, EvalConfig(force_per_kg=500.0)) as ev:  # 50 N of gravity: far beyond the grip
        r = ev.evaluate(pieces, poses, table=PLANE)
    assert not r.success and r.reason == "object_left_on_table"
    assert r.direction_translation_m[0] > 0.05  # it stayed ~10 cm below where the hand took it


def test_hand_in_the_table_is_one_for_one_and_rejected(evaluator, held):
    pieces, poses = held
    depths = []
    for sink in np.arange(0.0, 0.01, 0.001):  # the table moved into the hand, 1 mm per step
        scene, datas = evaluator.scene(pieces, None, (*PLANE[:3], PLANE[3] - 0.02 - sink))
        depths.append(table_depth(scene, datas[-1], poses[1]))
    depths = np.array(depths)
    inside = depths > 0
    assert inside.sum() >= 5 and np.allclose(np.diff(depths[inside]), 0.001, atol=1e-6), depths
    deep = (*PLANE[:3], PLANE[3] - 0.02 - float(np.arange(0.0, 0.01, 0.001)[np.argmax(depths > 0.002)]))
    r = evaluator.evaluate(pieces, poses, table=deep)
    assert r.reason == "hand_in_table" and not r.success and r.table_penetration_m > 0.002


@pytest.mark.parametrize("rise_max, rise_end, moved, reason", [
    (0.01, 0.0, 0.1, "object_left_on_table"), (0.09, 0.02, 0.08, "object_dropped"),
    (0.1, 0.09, 0.06, "object_slipped")])
def test_lift_failure_codes(rise_max, rise_end, moved, reason):
    res = LiftResult(DirectionResult(False, moved, 3.0), rise_max, rise_end, 300)
    assert lift_reason(res, EvalConfig()) == reason
    assert lift_reason(LiftResult(DirectionResult(True, 0.01, 3.0), 0.1, 0.1, 300), EvalConfig()) is None
    assert lift_reason(LiftResult(DirectionResult(False, np.inf, np.inf, True), 0.0, 0.0, 3), EvalConfig()) == "unstable"
