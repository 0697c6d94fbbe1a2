"""Every installed hand builds an evaluation scene and runs the protocol (not only Shadow)."""

import mujoco
import numpy as np
import pytest
import torch

from datagen.eval import EvalConfig, Evaluator
from datagen.hands import available_hands, load_hand

from .grasps import box_pieces

pytestmark = pytest.mark.mujoco


@pytest.mark.parametrize("name", ["shadow", "leap", "allegro", "shadow_e3m5"])
def test_hand_scene_and_free_flight(name, box_dir):
    if name not in available_hands():
        pytest.skip(f"{name} needs `make hands`")
    torch.set_num_threads(1)
    hand = load_hand(name)
    pieces = box_pieces((0.03, 0.02, 0.025), box_dir, name=f"box_{name}")
    # protocol uniform: the same gains for every hand (the default's per-hand gains: test_protocol.py)
    cfg = EvalConfig(min_touching_links=0, stop_at_first_failure=False, protocol="uniform")
    with Evaluator(hand, cfg) as ev:
        scene, _ = ev.scene(pieces)
        m = scene.model
        # the uniform gains on every hand actuator, contact parameters on every geom
        assert np.all(m.actuator_gainprm[scene.actuators, 0] == 5.0)
        assert np.all(m.actuator_biasprm[scene.actuators, 1] == -5.0)
        assert np.all(m.actuator_forcerange[scene.actuators] == [-3.0, 3.0])
        assert np.all(m.geom_condim == 4) and np.allclose(m.geom_friction[:, :2], [0.6, 0.02])
        assert np.allclose(m.geom_solref[scene.hand_geoms], [0.005, 1.0])
        assert abs(scene.object_mass - 0.1) < 1e-12 and m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        # hand 0.5 m away at its open pose: no contact, and in simulation nothing holds the box
        row = np.concatenate([[0.5, 0.5, 0.5, 1, 0, 0, 0], hand.open_pose.numpy()])
        poses = np.stack([row, row, row])
        r = ev.evaluate(pieces, poses)
        assert r.touching_links == 0 and r.reason == "slipped_+x" and r.direction_success == (False,) * 6
        expected = 10.0 * 0.004**2 * 50 * 49 / 2  # free flight at 10 m/s^2, first check (see test_evaluate)
        assert np.allclose(r.direction_translation_m, expected, atol=1e-9)
    with Evaluator(hand, EvalConfig()) as ev:
        assert ev.evaluate(pieces, poses).reason == "no_contact"


@pytest.mark.parametrize("name", ["shadow", "leap", "allegro"])
def test_fingers_reach_a_step_target_within_a_protocol_phase(name, box_dir):
    # position actuators at the protocol's kp with damping kv <= kp * 0.1 s: a free finger joint
    # stepped 0.3 rad closes >= 90% of the step within one phase (0.4 s), on every hand
    if name not in available_hands():
        pytest.skip(f"{name} needs `make hands`")
    hand = load_hand(name)
    with Evaluator(hand, EvalConfig()) as ev:
        scene, _ = ev.scene(box_pieces((0.03, 0.02, 0.025), box_dir, name=f"box_{name}"))
        m = scene.model
        assert np.all(-m.actuator_biasprm[scene.actuators, 2] <= 5.0 * 0.1 + 1e-12)
        d = mujoco.MjData(m)
        q0 = hand.open_pose.numpy()
        d.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = d.mocap_pos[scene.mocap] = [0.5, 0.5, 0.5]
        d.qpos[scene.hand_qpos_adr] = scene.hand_joints(q0)  # the simulated joints (a held wrist is not)
        sim = np.arange(hand.num_joints) if scene.sim_joints is None else scene.sim_joints
        k = int(np.argmax((hand.joint_upper.numpy() - q0)[sim]))  # the joint with the most room to flex
        j = int(sim[k])
        target = q0.copy()
        target[j] += 0.3
        d.ctrl[scene.actuators] = scene.ctrl(target)
        mujoco.mj_step(m, d, nstep=100)  # 0.4 s at 4 ms
        assert d.qpos[scene.hand_qpos_adr[k]] - q0[j] > 0.27, (name, hand.joint_names[j])
