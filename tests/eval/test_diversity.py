"""Grasp diversity (datagen/eval/diversity.py) against hand-computed cases and independent code
(scipy's rotations, torch's histc, the eigenvalues of the sample covariance)."""

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from datagen.eval.diversity import grasp_diversity, joint_entropy, pca_explained_variance, pose_features


def _row(pos, quat_wxyz, joints):
    return np.concatenate([pos, quat_wxyz, joints])


def test_pose_features_hand_case():
    # object turned +90 deg about z; a hand at world (1, 0, 0) with the identity orientation sits
    # at (0, -1, 0) in the object frame, turned -90 deg about z
    c = math.cos(math.pi / 4)
    row = _row([1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.3, -0.2])
    f = pose_features(row[None], np.array([0.0, 0.0, 0.0, c, 0.0, 0.0, c]))
    assert f.shape == (1, 8)
    np.testing.assert_allclose(f[0], [0.0, -1.0, 0.0, 0.0, 0.0, -math.pi / 2, 0.3, -0.2], atol=1e-12)


def test_pose_features_match_scipy_rotations():
    rng = np.random.default_rng(3)
    r_hand, r_obj = Rotation.random(64, random_state=4), Rotation.random(64, random_state=5)
    p_hand, p_obj = rng.normal(size=(64, 3)), rng.normal(size=(64, 3))
    rows = np.concatenate([p_hand, np.roll(r_hand.as_quat(), 1, axis=1), rng.normal(size=(64, 5))], axis=1)
    obj = np.concatenate([p_obj, np.roll(r_obj.as_quat(), 1, axis=1)], axis=1)
    rows[::2, 3:7] *= -1.0  # the same rotation with the other quaternion sign
    f = pose_features(rows, obj)
    np.testing.assert_allclose(f[:, :3], r_obj.inv().apply(p_hand - p_obj), atol=1e-12)
    np.testing.assert_allclose(f[:, 3:6], (r_obj.inv() * r_hand).as_rotvec(), atol=1e-9)
    assert np.all(np.linalg.norm(f[:, 3:6], axis=1) <= math.pi + 1e-12)
    np.testing.assert_array_equal(f[:, 6:], rows[:, 7:])


def test_pca_hand_computed_ratios():
    # four points (+-2, 0), (0, +-1): variances 8/3 and 2/3 along the axes, so 0.8 then 1
    x = np.array([[2.0, 0.0], [-2.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    np.testing.assert_allclose(pca_explained_variance(x), [0.8, 1.0, 1.0, 1.0, 1.0])
    # a shift and a rotation of the point set change nothing
    c, s = math.cos(0.7), math.sin(0.7)
    np.testing.assert_allclose(pca_explained_variance(x @ np.array([[c, s], [-s, c]]) + 5.0),
                               [0.8, 1.0, 1.0, 1.0, 1.0])


def test_pca_matches_covariance_eigenvalues():
    x = np.random.default_rng(0).normal(size=(40, 12)) * np.linspace(0.1, 3.0, 12)
    ev = np.sort(np.linalg.eigvalsh(np.cov(x, rowvar=False)))[::-1]
    np.testing.assert_allclose(pca_explained_variance(x, components=7), np.cumsum(ev)[:7] / ev.sum())


def test_pca_undefined_cases():
    assert np.all(np.isnan(pca_explained_variance(np.ones((1, 4)))))
    assert np.all(np.isnan(pca_explained_variance(np.ones((6, 4)))))  # no variance


def test_joint_entropy_hand_cases():
    lo, hi = np.array([0.0]), np.array([3.2])
    one_per_bin = (np.arange(32) + 0.5)[:, None] * 0.1
    assert joint_entropy(one_per_bin, lo, hi) == pytest.approx(math.log(32))
    assert joint_entropy(np.full((9, 1), 1.0), lo, hi) == 0.0
    # the upper limit is in the last bin; a value outside the limits is not counted
    assert joint_entropy(np.array([[0.0], [3.2], [3.3], [-0.1]]), lo, hi) == pytest.approx(math.log(2))
    # mean over joints: ln 2 and 0
    two = np.array([[0.0, 1.0], [3.2, 1.0]])
    assert joint_entropy(two, np.array([0.0, 0.0]), np.array([3.2, 2.0])) == pytest.approx(math.log(2) / 2)
    np.testing.assert_allclose(joint_entropy(two, np.array([0.0, 0.0]), np.array([3.2, 2.0]), per_joint=True),
                               [math.log(2), 0.0])
    # a joint with no value in range counts 0 (the peer's NaN set to 0)
    assert joint_entropy(np.array([[5.0], [6.0]]), lo, hi) == 0.0
    with pytest.raises(ValueError):
        joint_entropy(two, lo, hi)


def test_joint_entropy_matches_torch_histc():
    rng = np.random.default_rng(1)
    lo, hi = np.array([-0.35, 0.0, -1.0]), np.array([0.35, 1.57, 2.5])
    q = rng.uniform(lo - 0.1, hi + 0.1, size=(200, 3))  # some outside the limits
    q[:5] = hi  # exactly at the upper limit
    ref = []
    for j in range(3):
        counts = torch.as_tensor(q[:, j]).histc(32, float(lo[j]), float(hi[j]))
        p = counts / counts.sum()
        ref.append(float(-(p * torch.log(torch.where(p > 0, p, torch.ones_like(p)))).sum()))
    np.testing.assert_allclose(joint_entropy(q, lo, hi, per_joint=True), ref, rtol=1e-9)


def test_grasp_diversity_of_rows():
    rng = np.random.default_rng(2)
    rows = np.concatenate([rng.normal(size=(30, 3)) * 0.05, np.tile([1.0, 0, 0, 0], (30, 1)),
                           rng.uniform(0, 1, size=(30, 4))], axis=1)
    d = grasp_diversity(rows, np.zeros(4), np.ones(4))
    assert d.n == 30 and len(d.pca) == 5
    np.testing.assert_allclose(d.pca, pca_explained_variance(pose_features(rows)))
    assert d.joint_entropy == pytest.approx(joint_entropy(rows[:, 7:], np.zeros(4), np.ones(4)))
    empty = grasp_diversity(np.zeros((0, 11)), np.zeros(4), np.ones(4))
    assert empty.n == 0 and math.isnan(empty.joint_entropy)


def test_grouped_diversity_hand_cases():
    from datagen.eval.diversity import grouped_diversity

    lo, hi = np.array([0.0, 0.0]), np.array([3.2, 2.0])
    still = _row([0.0, 0.0, 0.1], [1.0, 0, 0, 0], [1.0, 1.0])
    rows = np.stack([_row([0.1, 0.0, 0.0], [1.0, 0, 0, 0], [0.0, 1.0]), still, still,
                     _row([-0.1, 0.0, 0.0], [1.0, 0, 0, 0], [3.2, 1.0])])
    keys = [("fc", 0.08), ("fc", 0.06), ("fc", 0.06), ("fc", 0.08)]
    (k1, d1), (k2, d2) = grouped_diversity(rows, keys, lo, hi)
    assert (k1, k2) == (("fc", 0.06), ("fc", 0.08))  # sorted keys
    # 0.06: two identical grasps: no variance (PCA undefined), every joint in one bin
    assert d1.n == 2 and np.all(np.isnan(d1.pca)) and d1.joint_entropy == 0.0
    # 0.08: two grasps differing along one direction: the first component explains everything;
    # joint 1 in two bins (ln 2), joint 2 in one (0)
    assert d2.n == 2 and d2.pca == pytest.approx((1.0,) * 5) and d2.joint_entropy == pytest.approx(math.log(2) / 2)
    with pytest.raises(ValueError):
        grouped_diversity(rows, keys[:3], lo, hi)
