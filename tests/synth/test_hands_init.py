"""Initial poses and a short synthesis are sane for every built-in hand (palm faces the object,
no hand-object penetration at the start, fingertips reach the surface)."""

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.tasks import TaskSpec, load_task
from datagen.synth.init import initial_poses
from tests.hands.conftest import hand_params


@pytest.fixture(scope="module")
def box():
    mesh = trimesh.creation.box(extents=[1.0, 0.7, 1.4])
    mesh.apply_scale(1.0 / np.linalg.norm(0.5 * mesh.extents))
    return GraspTarget.from_mesh(mesh, 0.08, "box")


@pytest.mark.parametrize("name", hand_params())
@pytest.mark.parametrize("init", [
    {"kind": "surround"},
    {"kind": "approach", "approach": [0, 0, -1], "thumb": [1, 0, 0], "roll_deg": 10},
    {"kind": "wrap", "curl": 0.3, "roll_deg": 20},
])
@pytest.mark.slow
def test_initial_poses_face_the_object_without_touching_it(name, init, box):
    hand = load_hand(name)
    spec = TaskSpec.from_dict({"name": "t", "init": init}).init
    B = 32
    root, joints = initial_poses(hand, [box], torch.zeros(B, dtype=torch.long), spec, torch.Generator().manual_seed(0))
    palm = hand.palm_frame(root, joints)
    to_centre = torch.nn.functional.normalize(-palm.origin, dim=-1)
    assert ((palm.approach * to_centre).sum(-1) > 0.5).float().mean() > 0.9
    centres, radii = hand.spheres(root, joints)
    clearance = box.query(centres).distance - radii  # exact mesh distance of every collision sphere
    assert (clearance.amin(-1) > -0.003).float().mean() > 0.9, f"{name}: the open hand starts inside the object"


@pytest.mark.slow
@pytest.mark.parametrize("name", [p for p in hand_params() if p.values[0] != "shadow"])  # shadow: test_synthesize
def test_short_force_closure_synthesis_reaches_the_surface(name, box):
    hand = load_hand(name)
    cfg = SynthConfig.from_dict({"iters": 300, "seed": 0, "weights": {"self_penetration": 0.0} if name == "leap" else {}})
    res = synthesize(hand, [box], load_task("force_closure"), cfg, 4)
    assert res.usable(0.005).float().mean() >= 0.5, (name, res.tip_distance, res.max_penetration)
    assert torch.isfinite(res.squeeze).all() and torch.isfinite(res.pregrasp).all()


@pytest.mark.parametrize("name", hand_params())
def test_curled_fingers_flex_towards_the_palm_face_in_mujoco(name):
    """``init.curl``: checked with MuJoCo's own kinematics of the hand model, every fingertip of
    the curled hand moves out of the palm's face (along its approach axis), more for a deeper
    curl, and sideways (abduction) joints stay at the open pose."""
    import mujoco

    from datagen.synth.init import curled_joints

    hand = load_hand(name)
    m = hand.mj_model
    d = mujoco.MjData(m)
    tip_bodies = [m.body(hand.link_names[i]).id for i in hand.fingertip_link_index.tolist()]
    palm_body = m.body(hand.link_names[hand.palm_link]).id

    def tips_along_palm_normal(joints):
        d.qpos[:] = hand.joints_to_qpos(joints)
        mujoco.mj_kinematics(m, d)
        normal = d.xmat[palm_body].reshape(3, 3) @ hand.palm_local[1].cpu().numpy()
        return d.xpos[tip_bodies] @ (normal / np.linalg.norm(normal))

    open_ = tips_along_palm_normal(hand.open_pose)
    half, deep = (tips_along_palm_normal(curled_joints(hand, f)) for f in (0.3, 0.6))
    assert (half - open_ > 0.01).all(), (name, half - open_)  # every tip at least 1 cm out of the palm's face
    assert (deep - half > 0.0).all(), (name, deep - half)
    q = curled_joints(hand, 0.6)
    assert torch.all(q <= hand.joint_upper + 1e-9) and torch.all(q >= hand.joint_lower - 1e-9)
    if name == "shadow":  # abduction joints (side-to-side) are not flexion
        for j in ("robot0:FFJ3", "robot0:MFJ3", "robot0:RFJ3", "robot0:LFJ3"):
            assert float(q[m.joint(j).id]) == pytest.approx(float(hand.open_pose[m.joint(j).id]))
    assert torch.equal(curled_joints(hand, 0.0), hand.apply_couplings(hand.open_pose))


def test_curl_outside_zero_one_is_a_config_error():
    from datagen.synth.config import ConfigError

    with pytest.raises(ConfigError, match="init.curl"):
        TaskSpec.from_dict({"name": "t", "init": {"kind": "approach", "curl": 1.5}})


@pytest.mark.slow
@pytest.mark.parametrize("name", hand_params())
def test_aim_fingertips_puts_the_pinch_on_the_target_in_mujoco(name, box):
    """``init.aim: fingertips`` with a ``thumb`` hint: checked with MuJoCo's own kinematics of the
    hand model, the midpoint of the two farthest apart task fingertips lands ``distance_m`` above
    ``target_m`` (against the approach), the thumb-to-fingers pinch vector points along the hint,
    and the palm's normal leans only within the plane of the approach and the hint."""
    import mujoco

    hand = load_hand(name)
    m = hand.mj_model
    d = mujoco.MjData(m)
    fingers = [hand.fingertip_names.index(f) for f in ("th", "ff", "mf")]
    target = np.array([0.01, -0.02, 0.005])
    spec = TaskSpec.from_dict({"name": "t", "init": {
        "kind": "approach", "approach": [0, 0, -1], "thumb": [0, 1, 0], "roll_deg": 0, "tilt_deg": 0,
        "offset_m": 0, "aim": "fingertips", "curl": 0.3, "distance_m": [0.01, 0.01], "target_m": target.tolist()}}).init
    root, joints = initial_poses(hand, [box], torch.zeros(2, dtype=torch.long), spec, torch.Generator().manual_seed(0),
                                 tip_index=fingers)
    root, joints = root[0].double().numpy(), joints[0]
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, root[3:7] / np.linalg.norm(root[3:7]))
    R = R.reshape(3, 3)
    d.qpos[:] = hand.joints_to_qpos(joints)
    mujoco.mj_kinematics(m, d)
    local = hand.fingertip_points_local.double().numpy()
    tips = []
    for f in fingers:
        b = m.body(hand.link_names[int(hand.fingertip_link_index[f])]).id
        tips.append(R @ (d.xpos[b] + d.xmat[b].reshape(3, 3) @ local[f]) + root[:3])
    tips = np.array(tips)
    gaps = np.linalg.norm(tips[:, None] - tips[None], axis=-1)
    i, j = np.unravel_index(gaps.argmax(), gaps.shape)
    np.testing.assert_allclose(0.5 * (tips[i] + tips[j]), target + [0, 0, 0.01], atol=1e-4)
    pinch = tips[0] - tips[1:].mean(0)
    assert pinch[1] / np.linalg.norm(pinch) > 0.999, (name, pinch)
    palm_body = m.body(hand.link_names[hand.palm_link]).id
    normal = R @ d.xmat[palm_body].reshape(3, 3) @ hand.palm_local[1].double().numpy()
    normal /= np.linalg.norm(normal)
    assert abs(normal[0]) < 1e-3 and normal[2] < -0.3, (name, normal)


def test_aim_must_be_palm_or_fingertips():
    from datagen.synth.config import ConfigError

    with pytest.raises(ConfigError, match="init.aim"):
        TaskSpec.from_dict({"name": "t", "init": {"kind": "approach", "aim": "tips"}})


def test_wrap_puts_the_pinch_across_a_box_thinnest_side():
    """``wrap`` on a 20 x 10 x 5 cm box turned by a known rotation (hand-computed axes: R's
    columns): without jitter every palm faces the box across its 20 cm length and every pinch
    axis (thumb tip minus the other tips, by the hand's own kinematics) lies across it too;
    with the section's widths 10 : 5 cm the pinch axis is drawn near the 5 cm side (median angle
    atan(0.25) = 14 deg from it), and the palm starts distance_m outside the box's face."""
    hand = load_hand("shadow")
    R = torch.tensor(trimesh.transformations.random_rotation_matrix(np.random.default_rng(3).random(3))[:3, :3],
                     dtype=torch.float32)
    ext = np.array([0.2, 0.1, 0.05])
    mesh = trimesh.creation.box(extents=ext / np.linalg.norm(ext / 2))
    T = np.eye(4)
    T[:3, :3] = R.double().numpy()
    mesh.apply_transform(T)
    box = GraspTarget.from_mesh(mesh, float(np.linalg.norm(ext / 2)), "box", grid_resolution=16)
    init = TaskSpec.from_dict({"name": "t", "init": {"kind": "wrap", "curl": 0.3, "roll_deg": 0, "tilt_deg": 0,
                                                     "offset_m": 0.0}}).init
    B = 256
    root, joints = initial_poses(hand, [box], torch.zeros(B, dtype=torch.long), init, torch.Generator().manual_seed(0))
    long_, thin = R[:, 0], R[:, 2]
    tips = hand.fingertip_points(root, joints)  # (B, 5, 3), the thumb first
    pinch = torch.nn.functional.normalize(tips[:, 0] - tips[:, 1:].mean(1), dim=-1)
    palm = hand.palm_frame(root, joints)
    # across the length, to the axes' estimate from 2048 hull samples (within 2 deg)
    assert torch.all((pinch @ long_).abs() < 0.035)
    assert torch.all((palm.approach @ long_).abs() < 0.035)
    angle = torch.rad2deg(torch.acos((pinch @ thin).abs().clamp(max=1)))
    assert 8 < float(angle.median()) < 20, float(angle.median())
    n = torch.nn.functional.normalize(palm.origin - (palm.origin @ long_)[:, None] * long_, dim=-1)
    face = 0.5 * (torch.tensor(ext, dtype=torch.float32) * (n @ R).abs()).sum(-1)  # the box's support along n
    out = (palm.origin * n).sum(-1) - face
    assert torch.all(out > init.distance_m[0] - 0.01) and torch.all(out < init.distance_m[1] + 0.003)
    assert torch.all((palm.approach * n).sum(-1) < -0.95)  # facing the box
    slide = palm.origin @ long_
    assert float(slide.abs().max()) <= 0.25 * 0.1 + 0.002 and float(slide.std()) > 0.01
