"""``hand_root: palm``: the hand rooted at the palm, wrist joints held at the row's values.

Reference: MuJoCo's own kinematics of the full scene (forearm, wrist joints): at any row, every
link from the palm on must be where the full model puts it."""

import numpy as np
import pytest

from datagen.eval import EvalConfig, EvalError, build_scene
from datagen.eval.metrics import set_static_pose
from tests.eval.grasps import box_grasp, box_pieces

import mujoco


def test_palm_scene_puts_every_link_where_the_full_hand_does(shadow, box_dir):
    pieces = box_pieces((0.03, 0.02, 0.03), box_dir)
    full = build_scene(shadow, pieces, EvalConfig(hand_root="spec"))
    palm = build_scene(shadow, pieces, EvalConfig(hand_root="palm"))
    held = {n for n in shadow.joint_names if "WRJ" in n}
    assert palm.model.nv == full.model.nv - len(held)  # the wrist dofs are gone
    assert palm.model.nu == full.model.nu - len(held)
    assert "hand/robot0:forearm" not in {palm.model.body(b).name for b in range(palm.model.nbody)}
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.normal(size=4)
        row = np.concatenate([rng.normal(size=3) * 0.1, q / np.linalg.norm(q), rng.uniform(-0.4, 0.4, shadow.num_joints)])
        df, dp = mujoco.MjData(full.model), mujoco.MjData(palm.model)
        set_static_pose(full, df, row)
        set_static_pose(palm, dp, row)
        for b in range(1, palm.model.nbody):
            name = palm.model.body(b).name
            if not name.startswith("hand/"):
                continue
            bf = full.model.body(name).id
            np.testing.assert_allclose(dp.xpos[b], df.xpos[bf], atol=1e-12, err_msg=name)
            np.testing.assert_allclose(dp.xmat[b], df.xmat[bf], atol=1e-12, err_msg=name)


def test_palm_rooted_evaluation_holds_a_constructed_grasp(shadow, box_dir):
    from datagen.eval import Evaluator

    with Evaluator(shadow, EvalConfig(hand_root="spec")) as full, Evaluator(shadow, EvalConfig(hand_root="palm")) as palm:
        pieces, poses = box_grasp(full, (0.03, 0.015, 0.03), 0.0, box_dir)
        a, b = full.evaluate(pieces, poses), palm.evaluate(pieces, poses)
    assert a.reason == b.reason == "ok"
    assert a.penetration_m == pytest.approx(b.penetration_m, abs=1e-12)  # same static pose


def test_unknown_hand_root_is_refused():
    with pytest.raises(EvalError, match="hand_root"):
        EvalConfig(hand_root="wrist")
