"""Grasp synthesis end to end on small primitives (Shadow hand), plus its building blocks."""

import mujoco
import numpy as np
import pyarrow.parquet as pq
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.synth import ConfigError, GraspTarget, SynthConfig, synthesize
from datagen.tasks import TaskSpec, load_task
from datagen.synth.energies import contact_sphere_index, evaluate_state, hand_object_state
from datagen.synth.init import initial_poses
from datagen.rotation import axis_angle_to_quat, matrix_to_quat, quat_multiply, quat_to_matrix
from datagen.synth.rows import result_table
from schemas import check_version


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


def _normalized(mesh):
    mesh.apply_translation(-mesh.bounds.mean(0))
    return mesh.apply_scale(1.0 / np.linalg.norm(0.5 * mesh.extents))


@pytest.fixture(scope="module")
def box():
    return GraspTarget.from_mesh(_normalized(trimesh.creation.box(extents=[1.0, 0.7, 1.4])), 0.08, "box")


@pytest.fixture(scope="module")
def sphere():
    return GraspTarget.from_mesh(_normalized(trimesh.creation.icosphere(3)), 0.07, "sphere")


@pytest.fixture(scope="module")
def fc_run(hand, box, sphere):
    cfg = SynthConfig(iters=250, seed=1)
    res = synthesize(hand, [box, sphere], load_task("force_closure"), cfg, 6)
    return cfg, res


@pytest.mark.slow
def test_force_closure_synthesis_reaches_contact_without_penetration(fc_run):
    cfg, res = fc_run
    gap = res.tip_distance.abs().amax(-1)  # worst fingertip of each grasp, m
    pen = res.max_penetration
    for k, name in enumerate(["box", "sphere"]):
        sel = res.object_index == k
        in_contact = (gap[sel] <= 0.005).float().mean().item()
        shallow = (pen[sel] <= 0.002).float().mean().item()
        assert in_contact >= 0.6, f"{name}: only {in_contact:.0%} of grasps have all fingertips within 5 mm"
        assert shallow >= 0.8, f"{name}: only {shallow:.0%} of grasps penetrate less than 2 mm"
        assert (res.energies["distance"][sel].median() < 0.005**2 * 5)


@pytest.mark.slow
def test_task_energy_decreases_from_the_initial_pose(hand, box, fc_run):
    cfg, res = fc_run
    task = load_task("force_closure")
    dirs = torch.nn.functional.normalize(torch.randn(256, 6, generator=torch.Generator().manual_seed(0)), dim=-1)
    spheres = contact_sphere_index(hand)
    idx = list(range(5))
    init = hand_object_state(hand, [box], torch.zeros(6, dtype=torch.long), res.initial[:6, :7], res.initial[:6, 7:], spheres[idx])
    final = hand_object_state(hand, [box], torch.zeros(6, dtype=torch.long), res.grasp[:6, :7], res.grasp[:6, 7:], spheres[idx])
    cfg = cfg.for_hand(hand)
    e0, e1 = evaluate_state(init, cfg, task, dirs), evaluate_state(final, cfg, task, dirs)
    assert e1.task.mean() < e0.task.mean() - 0.05
    assert (e1.total < e0.total).all()


@pytest.mark.slow
def test_pregrasp_squeeze_relation(hand, fc_run):
    _, res = fc_run
    assert torch.equal(res.pregrasp[:, :7], res.grasp[:, :7]) and torch.equal(res.squeeze[:, :7], res.grasp[:, :7])
    # the pregrasp mirrors the squeeze about the grasp, or a 1/2^k of that opening where the full one
    # sinks the hand deeper into the object (backtrack_pregrasp); the wrist stays put
    g, pre, sq = res.grasp[:, 7:], res.pregrasp[:, 7:], res.squeeze[:, 7:]
    for b in range(g.shape[0]):
        fits = [torch.allclose(pre[b], hand.apply_couplings(g[b:b + 1] + a * (g[b:b + 1] - sq[b:b + 1]))[0], atol=1e-6)
                for a in (1.0, 0.5, 0.25, 0.125, 0.0625, 0.0)]
        assert any(fits), b
    assert torch.equal(res.squeeze[:, 7:9], res.grasp[:, 7:9])
    # squeezing closes the fingers onto the object: the contact spheres move inwards
    from datagen.synth.energies import contact_sphere_index
    tips = contact_sphere_index(hand)
    c_g, _ = hand.spheres(res.grasp[:, :7], res.grasp[:, 7:])
    c_s, _ = hand.spheres(res.squeeze[:, :7], res.squeeze[:, 7:])
    inward = ((c_s[:, tips] - c_g[:, tips]) * res.contact_normals).sum(-1)
    assert (inward > 0).float().mean() > 0.9


def test_seeded_run_is_bit_reproducible(hand, box):
    cfg = SynthConfig(iters=20, seed=7)
    a = synthesize(hand, [box], load_task("force_closure"), cfg, 3)
    b = synthesize(hand, [box], load_task("force_closure"), cfg, 3)
    assert torch.equal(a.grasp, b.grasp) and torch.equal(a.initial, b.initial)
    c = synthesize(hand, [box], load_task("force_closure"), SynthConfig(iters=20, seed=8), 3)
    assert not torch.equal(a.initial, c.initial)


def test_initial_palm_faces_the_object(hand, box):
    task = load_task("force_closure")
    root, joints = initial_poses(hand, [box], torch.zeros(64, dtype=torch.long), task.init, torch.Generator().manual_seed(0))
    palm = hand.palm_frame(root, joints)
    to_centre = torch.nn.functional.normalize(-palm.origin, dim=-1)
    assert ((palm.approach * to_centre).sum(-1) > 0.5).float().mean() > 0.9
    d = box.query(palm.origin).distance
    assert (d > 0.02).all() and (d < 0.08).all()  # 3-6 cm from the hull, plus jitter
    assert torch.equal(joints, hand.open_pose.expand(64, -1))


def test_approach_init_places_the_palm_as_specified(hand, box):
    # palm approaching along -x, thumb up (+z), aimed at a point off the box's centre: the box's
    # face at x = +extent is the supporting plane, the palm origin sits 3-6 cm beyond it
    init = TaskSpec.from_dict({"name": "t", "init": {
        "kind": "approach", "approach": [-1, 0, 0], "thumb": [0, 0, 1], "target_m": [0, 0.01, -0.02],
        "roll_deg": 0, "tilt_deg": 0, "offset_m": 0, "distance_m": [0.03, 0.06]}}).init
    root, joints = initial_poses(hand, [box], torch.zeros(32, dtype=torch.long), init, torch.Generator().manual_seed(0))
    palm = hand.palm_frame(root, joints)
    face_x = 0.08 * box.sdf.vertices[:, 0].max()
    assert torch.allclose(palm.approach, torch.tensor([-1.0, 0, 0]).expand(32, 3), atol=1e-5)
    thumb = torch.nn.functional.normalize(palm.thumb - (palm.thumb * palm.approach).sum(-1, keepdim=True) * palm.approach, dim=-1)
    assert torch.allclose(thumb, torch.tensor([0, 0, 1.0]).expand(32, 3), atol=1e-5)
    gap = palm.origin[:, 0] - face_x
    assert (gap >= 0.03 - 1e-5).all() and (gap <= 0.06 + 1e-5).all() and gap.std() > 0.005
    assert torch.allclose(palm.origin[:, 1:], torch.tensor([0.01, -0.02]).expand(32, 2), atol=1e-5)


def test_quaternions_match_mujoco():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quat_to_matrix(torch.tensor(q))
    for qi, Ri in zip(q, R):
        ref = np.zeros(9)
        mujoco.mju_quat2Mat(ref, qi)
        assert np.allclose(Ri.numpy().reshape(-1), ref, atol=1e-12)
    back = matrix_to_quat(R).numpy()
    assert np.allclose(np.abs((back * q).sum(1)), 1.0, atol=1e-9)  # same rotation, sign free
    w = torch.tensor(rng.normal(size=(5, 3)))
    ref = np.zeros(4)
    for wi, qa in zip(w, axis_angle_to_quat(w)):
        mujoco.mju_axisAngle2Quat(ref, (wi / wi.norm()).numpy(), float(wi.norm()))
        assert np.allclose(qa.numpy(), ref, atol=1e-12)
    prod = quat_multiply(torch.tensor(q[:1]), torch.tensor(q[1:2]))[0].numpy()
    mujoco.mju_mulQuat(ref, q[0], q[1])
    assert np.allclose(prod, ref, atol=1e-12)


@pytest.mark.slow
def test_rows_follow_the_schema(hand, box, sphere, fc_run, tmp_path):
    cfg, res = fc_run
    table = result_table(res, [box, sphere], hand, load_task("force_closure"), cfg)
    pq.write_table(table, tmp_path / "g.parquet")
    back = pq.read_table(tmp_path / "g.parquet")
    check_version(back.schema)
    assert back.num_rows == 12 and len(set(back["grasp_id"].to_pylist())) == 12
    row = back.slice(0, 1).to_pylist()[0]
    assert len(row["grasp_qpos"]) == 7 + hand.num_joints
    assert np.allclose(row["grasp_qpos"], res.grasp[0].numpy(), atol=1e-6)
    assert row["object_id"] == "box" and row["contact_fingers"] == ["th", "ff", "mf", "rf", "lf"]
    assert back.schema.metadata[b"datagen.joint_names"].decode().count("robot0:") == hand.num_joints


@pytest.mark.parametrize("data, match", [
    ({"iters": 0}, "iters"),
    ({"weights": {"distance": -1}}, "distance"),
    ({"step_size": 1}, "unknown keys"),
    ({"task_energy_kind": "l1"}, "task_energy_kind"),
])
def test_bad_configs_are_named(data, match):
    with pytest.raises(ConfigError, match=match):
        SynthConfig.from_dict(data)


def test_bad_tasks_are_named(tmp_path, hand, box):
    with pytest.raises(ConfigError, match="unknown task"):
        load_task("juggle")
    bad = tmp_path / "t.yaml"
    bad.write_text("name: t\nw_t: [0, 0, 0, 0, 0, 0]\n")
    with pytest.raises(ConfigError, match="w_t"):
        load_task(bad)
    with pytest.raises(ValueError, match="fingertips"):
        synthesize(hand, [box], TaskSpec(name="t", fingers=("pinky",)), SynthConfig(iters=1), 1)
    # a fingertip the hand lacks (lf on four-finger hands) is dropped, the others stay
    res = synthesize(hand, [box], TaskSpec(name="t", fingers=("th", "pinky")), SynthConfig(iters=1), 1)
    assert res.fingers == ["th"]
    with pytest.raises(ConfigError, match="thumb"):
        TaskSpec.from_dict({"name": "t", "init": {"kind": "approach", "approach": [1, 0, 0], "thumb": [2, 0, 0]}})
