"""Scenery of the mounted task objects in the evaluation: where the boxes sit against the part
(hand-checked geometry), MuJoCo lets the part move through them but not the hand, a hand inside
them counts as penetration (depth grows one for one as the hand is lowered into the door), and a
pregrasp through the door is rejected before simulating."""

import mujoco
import numpy as np
import pytest

from datagen.eval import EvalConfig, EvalError, Evaluator, TaskTest
from datagen.eval.metrics import static_metrics
from datagen.eval.scene import build_scene, pieces_from_processed
from datagen.objects import task_objects as T
from datagen.objects.process import process_object
from datagen.objects.sources import resolve
from datagen.tasks import load_task, task_scenery

MOUNTED = {"lever_handle": "turn_handle", "knob2": "turn_knob2", "knob3": "turn_knob3", "button": "push_button",
           "drawer": "pull_drawer"}


def _pieces(name, tmp_path):
    ref = resolve("tasks", name, T.object_id(name))
    return pieces_from_processed(process_object(ref, root=tmp_path), T.build(name).scale_m)


@pytest.mark.parametrize("name", T.TASK_OBJECTS)
def test_mounted_parts_sit_on_their_scenery_and_free_objects_have_none(name):
    obj = T.build(name)
    if name not in MOUNTED:
        assert obj.scenery_m == ()
        return
    assert task_scenery(load_task(MOUNTED[name])) == obj.scenery_m
    lo = np.array([b[0] for b in obj.scenery_m])
    hi = np.array([b[1] for b in obj.scenery_m])
    v = np.asarray(obj.mesh.vertices)
    base = v[:, 2].min()  # the face the part is mounted by
    if name == "button":
        # the bezel's top 5 mm below the cap's top, its opening 1.5 mm clear of the 11 mm cap
        assert hi[:, 2].max() == pytest.approx(v[:, 2].max() - 0.005, abs=1e-6)
        cap = v[v[:, 2] > hi[:, 2].max()]
        assert np.hypot(cap[:, 0], cap[:, 1]).max() < 0.0125 - 0.001
    else:
        # door, panel, cabinet carcass: the part's back face lies on the scenery's front face
        assert hi[0, 2] == pytest.approx(base, abs=1e-6)
    # nothing above the mounting face is inside a box except, for the button, its collar under the bezel
    inside = np.all((v[:, None] > lo + 1e-6) & (v[:, None] < hi - 1e-6), axis=-1).any(-1)
    above = v[:, 2] > base + (0.004 if name == "button" else 1e-6)
    assert not (inside & above).any()


def test_bad_scenery_names_the_field():
    for bad in ([((0, 0, 0), (0, 1, 1))], [((0, 0), (1, 1))], [((0, 0, float("nan")), (1, 1, 1))], ["box"]):
        with pytest.raises(EvalError, match="scenery"):
            TaskTest(w_t=(0, 0, 1, 0, 0, 0), joint="slide", scenery=bad)


def test_drawer_slides_through_its_cabinet_but_the_hand_does_not(shadow, tmp_path):
    test = EvalConfig().task_test("pull_drawer")
    scene = build_scene(shadow, _pieces("drawer", tmp_path), EvalConfig(), test)
    m = scene.model
    assert len(scene.scenery_geoms) == len(T.build("drawer").scenery_m) == 5
    for g, (lo, hi) in zip(scene.scenery_geoms, T.build("drawer").scenery_m):
        assert m.geom_type[g] == int(mujoco.mjtGeom.mjGEOM_BOX)
        assert np.allclose(m.geom_pos[g], (np.array(lo) + np.array(hi)) / 2) and np.allclose(m.geom_size[g], (np.array(hi) - np.array(lo)) / 2)
    # pushed in by 1 N for 0.5 s with the hand parked 1 m away, the drawer runs into the carcass
    d = mujoco.MjData(m)
    d.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = [0, 0, 1.0]
    d.mocap_pos[scene.mocap] = [0, 0, 1.0]
    d.xfrc_applied[scene.object_body, 2] = -1.0
    mujoco.mj_step(m, d, nstep=250)
    assert d.qpos[scene.object_qpos] < -0.05
    # the hand sunk into the cabinet face 30 cm beside the drawer (its root 5 cm below it): MuJoCo
    # collides it with the scenery
    face = T.build("drawer").scenery_m[1][1][2]
    row = np.concatenate([[0.0, 0.3, face - 0.05, 1, 0, 0, 0], shadow.open_pose.numpy()])
    d = mujoco.MjData(m)
    static_metrics(scene, d, row, touch_distance=0.002, contact_distance=0.005)
    mujoco.mj_collision(m, d)
    pairs = {tuple(sorted((int(c.geom1), int(c.geom2)))) for c in d.contact[:d.ncon]}
    assert any(set(p) & set(scene.scenery_geoms.tolist()) and set(p) & set(scene.hand_geoms.tolist()) for p in pairs)


def test_hand_in_the_door_is_penetration_one_for_one(shadow, tmp_path):
    test = EvalConfig().task_test("turn_handle")
    scene = build_scene(shadow, _pieces("lever_handle", tmp_path), EvalConfig(), test)
    d = mujoco.MjData(scene.model)
    door_top = T.build("lever_handle").scenery_m[0][1][2]
    # palm down (root rotated 180 deg about x: the Shadow hand's fingers along its root's +z turn down),
    # 25 cm beside the lever: nothing near the object, only the door below
    base = np.concatenate([[0.25, 0.0, 0.0, 0, 1, 0, 0], shadow.open_pose.numpy()])
    depths = []
    for z in np.arange(0.70, 0.30, -0.002):  # the root 70 to 30 cm above the door, 2 mm steps
        row = base.copy()
        row[2] = door_top + z
        depths.append(static_metrics(scene, d, row, touch_distance=0.002, contact_distance=0.005).penetration)
    depths = np.array(depths)
    assert depths[0] == 0.0 and depths.max() > 0.015
    # lowered 2 mm per step, the deepest point goes 2 mm further into the flat door per step (until
    # it nears the middle of the 4 cm leaf, where the depth to the far face takes over)
    first = int(np.flatnonzero(depths > 0)[0])
    sink = depths[first:first + 8]
    assert sink[-1] < 0.02 and np.allclose(np.diff(sink), 0.002, atol=1e-6), sink


def test_pregrasp_through_the_door_is_rejected(shadow, tmp_path):
    pieces = _pieces("lever_handle", tmp_path)
    door_top = T.build("lever_handle").scenery_m[0][1][2]
    # palm down beside the lever, the fingertips 2 cm into the door (the root 47 cm above it)
    row = np.concatenate([[0.25, 0.0, door_top + 0.47, 0, 1, 0, 0], shadow.open_pose.numpy()])
    with Evaluator(shadow, EvalConfig()) as ev:
        res = ev.evaluate(pieces, np.stack([row, row, row]), task="turn_handle")
    assert res.reason == "penetration" and res.pregrasp_penetration_m > 0.015
