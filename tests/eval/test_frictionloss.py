"""``joint_frictionloss``: the dry friction of the hand's joints in the evaluation scene.

Reference: MuJoCo's own constraint rows. With the asset's friction (Menagerie's Shadow: 0.001 N m
on each of its 24 joints) every step carries one dof-friction row per hand joint; with 0 it
carries none, and the object's joint never gets one."""

import mujoco
import numpy as np
import pytest

from datagen.eval import EvalConfig, EvalError, Evaluator, build_scene
from tests.eval.grasps import box_grasp, box_pieces


def _friction_rows(scene) -> int:
    d = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, d)
    return int(np.count_nonzero(d.efc_type[:d.nefc] == mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF))


def test_hand_joint_friction_is_the_assets_or_the_configs(shadow, box_dir):
    pieces = box_pieces((0.03, 0.02, 0.03), box_dir)
    asset = build_scene(shadow, pieces, EvalConfig())
    off = build_scene(shadow, pieces, EvalConfig(joint_frictionloss=0.0))
    more = build_scene(shadow, pieces, EvalConfig(joint_frictionloss=0.05))
    hand_dofs = [i for i in range(asset.model.nv) if asset.model.jnt_type[asset.model.dof_jntid[i]] != mujoco.mjtJoint.mjJNT_FREE]
    assert len(hand_dofs) == shadow.num_joints
    assert _friction_rows(asset) == shadow.num_joints and _friction_rows(off) == 0
    assert np.allclose(more.model.dof_frictionloss[hand_dofs], 0.05)
    free = [i for i in range(more.model.nv) if i not in hand_dofs]  # hand root and object
    assert not more.model.dof_frictionloss[free].any()


def test_a_constructed_grasp_holds_with_and_without_joint_friction(shadow, box_dir):
    with Evaluator(shadow, EvalConfig()) as asset, Evaluator(shadow, EvalConfig(joint_frictionloss=0.0)) as off:
        pieces, poses = box_grasp(asset, (0.03, 0.015, 0.03), 0.0, box_dir)
        assert asset.evaluate(pieces, poses).reason == off.evaluate(pieces, poses).reason == "ok"


def test_negative_joint_friction_is_refused():
    with pytest.raises(EvalError, match="joint_frictionloss"):
        EvalConfig(joint_frictionloss=-0.001)
