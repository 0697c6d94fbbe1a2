"""datagen.rotation against MuJoCo's own quaternion routines (an independent implementation)."""

import mujoco
import numpy as np
import torch

from datagen.rotation import (axis_angle_to_quat, matrix_to_quat, quat_angle_np, quat_multiply, quat_to_matrix,
                              quat_to_matrix_np, rotate_about)


def _mj_mat(q):
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, q / np.linalg.norm(q))
    return m.reshape(3, 3)


def test_against_mujoco():
    rng = np.random.default_rng(0)
    for _ in range(50):
        q0, q1 = rng.normal(size=4), rng.normal(size=4)
        q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
        assert np.allclose(quat_to_matrix_np(q0), _mj_mat(q0), atol=1e-12)
        assert np.allclose(quat_to_matrix(torch.tensor(q0)).numpy(), _mj_mat(q0), atol=1e-12)
        prod = np.zeros(4)
        mujoco.mju_mulQuat(prod, q0, q1)
        assert np.allclose(quat_multiply(torch.tensor(q0), torch.tensor(q1)).numpy(), prod, atol=1e-12)
        back = matrix_to_quat(torch.tensor(_mj_mat(q0))).numpy()
        assert np.allclose(back, q0 * np.sign(q0[0]), atol=1e-9)
        # the angle between two orientations: MuJoCo's velocity that takes q0 to q1 in unit time
        vel = np.zeros(3)
        mujoco.mju_subQuat(vel, q1, q0)
        assert np.isclose(quat_angle_np(q0, q1), np.linalg.norm(vel), atol=1e-9)
        w = rng.normal(size=3)
        qa = np.zeros(4)
        mujoco.mju_axisAngle2Quat(qa, w / np.linalg.norm(w), np.linalg.norm(w))
        assert np.allclose(axis_angle_to_quat(torch.tensor(w)).numpy(), qa, atol=1e-12)
        v = rng.normal(size=3)
        rotated = rotate_about(torch.tensor(v), torch.tensor(w / np.linalg.norm(w)), torch.tensor(np.linalg.norm(w)))
        assert np.allclose(rotated.numpy(), _mj_mat(qa) @ v, atol=1e-12)
