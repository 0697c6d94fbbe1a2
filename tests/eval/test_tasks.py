"""Task tests from the task YAMLs: every benchmark task resolves, its wrench and its joint are
right (hand-computed, and MuJoCo's own compiled joint), and a bad YAML names the bad field."""

import mujoco
import numpy as np
import pytest

from datagen.eval import EvalConfig, EvalError, TaskTest
from datagen.eval.scene import build_scene, pieces_from_processed
from datagen.objects import task_objects as T
from datagen.objects.process import process_object
from datagen.objects.sources import resolve
from datagen.errors import ConfigError
from datagen.tasks import builtin_tasks, load_task, task_object, task_test_from_spec

BENCHMARK = ("turn_handle", "turn_knob2", "turn_knob3", "lift_handbag", "lift_plate", "push_button", "pull_drawer",
             "precision_lid", "precision_key", "precision_usba")


def test_the_ten_tasks_are_built_in():
    assert set(BENCHMARK) <= set(builtin_tasks())


@pytest.mark.parametrize("name", BENCHMARK)
def test_every_task_yaml_loads_and_its_test_resolves(name):
    spec = load_task(name)
    obj = task_object(spec)
    assert obj in T.TASK_OBJECTS
    test = EvalConfig().task_test(name)
    joint = T.build(obj).joint
    if name.startswith("precision"):
        assert test is None and spec.gamma_deg == 180  # six-direction hold test, force closure of the tips
        assert joint.kind == "free"
    else:
        assert spec.gamma_deg == 15 and test.w_t == pytest.approx(np.array(spec.w_t) / np.linalg.norm(spec.w_t))
        assert (test.joint, test.axis, test.anchor) == (joint.kind, joint.axis, joint.anchor_m)
        assert test.measure_from == "closed"  # the paper's test: the hand fixed, the object unmoved
        assert {"turn": "hinge", "push": "slide", "pull": "slide", "lift": "free"}[name.split("_")[0]] == test.joint
    # the palm aims at most a hand length (15 cm) off the object's bounding box (its frame, metres)
    ext = T.build(obj).mesh.extents
    assert np.all(np.abs(spec.init.target_m) <= ext / 2 + 0.15)
    assert set(spec.fingers) <= {"th", "ff", "mf", "rf", "lf"}


def test_hand_computed_disturbances():
    c = EvalConfig()
    # knob3: w_t = torque +z, 0.03 N m -> the disturbance is a pure torque of -0.03 N m about z
    w = c.task_test("turn_knob3").disturbance(0.1, 0.04, 10.0)
    assert np.allclose(w, [0, 0, 0, 0, 0, -0.03])
    # lever: w_t = torque -z, 0.075 N m -> +0.075 N m about z
    assert np.allclose(c.task_test("turn_handle").disturbance(0.1, 0.09, 10.0), [0, 0, 0, 0, 0, 0.075])
    # push button: w_t = -z force, 1 N -> the button is pushed back up by 1 N
    assert np.allclose(c.task_test("push_button").disturbance(0.1, 0.02, 10.0), [0, 0, 1.0, 0, 0, 0])
    # drawer: pull +z, 1 N -> pushed back in (-z) by 1 N
    assert np.allclose(c.task_test("pull_drawer").disturbance(0.1, 0.2, 10.0), [0, 0, -1.0, 0, 0, 0])


def test_mujoco_joint_of_the_lever_turns_about_its_pivot(shadow, tmp_path):
    test = EvalConfig().task_test("turn_handle")
    ref = resolve("tasks", "lever_handle", T.object_id("lever_handle"))
    p = process_object(ref, root=tmp_path)
    scale = T.build("lever_handle").scale_m
    scene = build_scene(shadow, pieces_from_processed(p, scale), EvalConfig(), test)
    m = scene.model
    j = m.joint("object_joint").id
    assert m.jnt_type[j] == int(mujoco.mjtJoint.mjJNT_HINGE)
    assert np.allclose(m.jnt_axis[j], [0, 0, 1]) and np.allclose(m.jnt_pos[j], test.anchor)
    # physics: with the hand parked 1 m away, a torque about z turns the lever about the pivot:
    # the pivot stays put while the lever's tip moves
    d = mujoco.MjData(m)
    d.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = [0, 0, 1.0]
    d.mocap_pos[scene.mocap] = [0, 0, 1.0]
    d.xfrc_applied[scene.object_body, 5] = 0.01
    mujoco.mj_step(m, d, nstep=50)
    R, pos = d.xmat[scene.object_body].reshape(3, 3), d.xpos[scene.object_body]
    pivot, tip = np.array(test.anchor), np.array(test.anchor) + [0.115, 0, 0.05]
    assert np.allclose(R @ pivot + pos, pivot, atol=1e-6)
    assert np.linalg.norm(R @ tip + pos - tip) > 1e-3


def _write(tmp_path, eval_block: str, extra: str = "") -> str:
    path = tmp_path / "bad.yaml"
    path.write_text("name: bad\nw_t: [0, 0, 0, 0, 0, 1]\ngamma_deg: 15\nfingers: [th, ff]\n" + extra
                    + "eval:\n" + eval_block)
    return str(path)


def test_mujoco_button_cap_bottoms_out_at_its_end_stop_and_rises_freely(shadow, tmp_path):
    test = EvalConfig().task_test("push_button")
    assert test.limits == (-0.004, None)
    ref = resolve("tasks", "button", T.object_id("button"))
    scene = build_scene(shadow, pieces_from_processed(process_object(ref, root=tmp_path), T.build("button").scale_m),
                        EvalConfig(), test)
    m = scene.model
    j = m.joint("object_joint").id
    assert m.jnt_limited[j] and m.jnt_range[j][0] == pytest.approx(-0.004)
    # physics, hand parked 1 m away: pushed down 2 s by 1 N, the cap stops 4 mm down (the
    # constraint's softness aside); pushed up, it passes any pass threshold (no stop above)
    for force, check in ((-1.0, lambda z: -0.0045 < z < -0.0038), (1.0, lambda z: z > 0.05)):
        d = mujoco.MjData(m)
        d.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = [0, 0, 1.0]
        d.mocap_pos[scene.mocap] = [0, 0, 1.0]
        d.xfrc_applied[scene.object_body, 2] = force
        mujoco.mj_step(m, d, nstep=500)
        assert check(float(d.qpos[m.jnt_qposadr[j]])), (force, float(d.qpos[m.jnt_qposadr[j]]))


@pytest.mark.parametrize("limits", [(0.01, None), (None, None), (None, -0.1), (0.0,), (float("nan"), 0.0)])
def test_bad_joint_limits_name_the_field(limits):
    with pytest.raises(EvalError, match="limits"):
        TaskTest(w_t=(0, 0, 1, 0, 0, 0), joint="slide", limits=limits)
    with pytest.raises(EvalError, match="limits"):
        TaskTest(w_t=(0, 0, 1, 0, 0, 0), joint="free", limits=(-0.01, 0.01))


@pytest.mark.parametrize("block, field", [
    ("  test: task\n  object: teapot\n", "eval.object"),
    ("  test: task\n", "eval.object"),
    ("  test: wiggle\n  object: knob2\n", "eval.test"),
    ("  test: task\n  object: knob2\n  torque: 1\n", "torque"),
    ("  test: task\n  object: knob2\n  torque_nm: -1\n", "torque_nm"),
    ("  test: task\n  object: knob2\n  max_rotation_deg: 0\n", "max_rotation_deg"),
    ("  test: task\n  object: knob2\n  measure_from: later\n", "measure_from"),
])
def test_bad_eval_block_names_the_field(tmp_path, block, field):
    with pytest.raises(EvalError, match=field):
        task_test_from_spec(load_task(_write(tmp_path, block)))


def test_bad_task_field_names_the_field(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text("name: g\ngamma_deg: 200\neval: {object: knob2}\n")
    with pytest.raises(ConfigError, match="gamma_deg"):
        load_task(path)
    path.write_text("name: g\ninit: {kind: approach, target: [0, 0, 0]}\n")
    with pytest.raises(ConfigError, match="target"):
        load_task(path)


def test_unknown_task_still_raises():
    with pytest.raises(EvalError, match="has no evaluation test"):
        EvalConfig().task_test("juggle_knives")
