"""The reference learner's pieces (examples/learn_grasps.py): grasp vectors encode and decode back
to the three poses (scipy's rotations as the reference) and a hand-computed case; the cloud's
signed distance against an analytic sphere; the hand's spheres in the model's frame against the
hand model's own FK from a quaternion root; retrieval by Chamfer distance; the bootstrap interval."""

import importlib.util
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

_spec = importlib.util.spec_from_file_location("learn_grasps",
                                               Path(__file__).parents[1] / "examples" / "learn_grasps.py")
learn = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("learn_grasps", learn)  # its dataclasses look their module up there
_spec.loader.exec_module(learn)


def _poses(n: int, lo: np.ndarray, hi: np.ndarray, seed: int = 0):
    rng = np.random.default_rng(seed)
    rot = Rotation.random(n, random_state=seed + 1)
    root = np.concatenate([rng.uniform(-0.15, 0.15, (n, 3)), np.roll(rot.as_quat(), 1, axis=1)], 1)
    grasp = np.concatenate([root, rng.uniform(lo, hi, (n, len(lo)))], 1)
    delta = rng.uniform(-0.2, 0.2, (n, len(lo)))
    pre, squeeze = grasp.copy(), grasp.copy()
    pre[:, 7:] -= delta
    squeeze[:, 7:] += 0.5 * delta
    return rot, pre, grasp, squeeze


def test_grasp_vectors_round_trip():
    lo, hi = np.array([-0.5, 0.0, 0.1]), np.array([0.5, 1.6, 1.2])
    rot, pre, grasp, squeeze = _poses(32, lo, hi)
    coder = learn.GraspCoder(lo, hi)
    coder.u_mean = torch.tensor([0.1, 0.02, -0.03])
    v = coder.encode(coder.pose_of(*(torch.tensor(x, dtype=torch.float32) for x in (pre, grasp, squeeze))))
    assert v.shape == (32, 9 + 3 * 3)
    p2, g2, s2 = coder.decode(v).qpos()
    np.testing.assert_allclose(g2[:, :3], grasp[:, :3], atol=1e-6)
    assert np.all((Rotation.from_quat(np.roll(g2[:, 3:7], -1, axis=1)) * rot.inv()).magnitude() < 1e-5)
    for a, b in ((p2, pre), (g2, grasp), (s2, squeeze)):
        np.testing.assert_allclose(a[:, 7:], b[:, 7:], atol=1e-5)
        np.testing.assert_array_equal(a[:, :7], g2[:, :7])  # one root for the three poses


def test_grasp_vector_hand_case():
    # the identity hand at (-0.1, 0, 0) m: the object's centre is 10 cm along the root's +x, in
    # 1 cm units; the rotation's columns in tenths; joints at the limits' midpoints are 0
    coder = learn.GraspCoder(np.array([0.0, -1.0]), np.array([1.0, 1.0]))
    g = torch.tensor([[-0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5, 0.0]])
    v = coder.encode(coder.pose_of(g, g, g))
    np.testing.assert_allclose(v.numpy(), [[10, 0, 0, 0, 10, 0, 10, 0, 0, 0, 0, 0, 0, 0, 0]], atol=1e-5)
    v[0, 9] = 10.0  # a decoded joint beyond its limit is clamped to it
    assert coder.decode(v).joints[0, 0] == 1.0


def test_signed_distance_of_a_sampled_sphere():
    # a 5 cm sphere sampled by 2000 points with its normals: the exact distance is |q| - 0.05
    g = torch.Generator().manual_seed(0)
    p = torch.randn(1, 2000, 3, generator=g)
    p = p / p.norm(dim=2, keepdim=True)
    q = torch.randn(1, 200, 3, generator=g)
    q = q / q.norm(dim=2, keepdim=True) * torch.linspace(0.01, 0.09, 200)[None, :, None]
    sd = learn.signed_distance(q, 0.05 * p, p)
    exact = q.norm(dim=2) - 0.05
    assert torch.all(torch.sign(sd) == torch.sign(exact))
    assert (sd - exact).abs().max() < 0.004  # the sample's spacing, ~2 mm


def test_hand_spheres_in_the_model_frame_match_the_hand_model():
    from datagen.hands import load_hand

    hand = load_hand("shadow")
    lo, hi = hand.joint_lower.numpy(), hand.joint_upper.numpy()
    _, pre, grasp, squeeze = _poses(6, lo, hi)
    coder, geo = learn.GraspCoder(lo, hi), learn.HandGeometry(hand)
    g = torch.tensor(grasp, dtype=torch.float32)
    centres, radii = geo.spheres(coder.pose_of(g, g, g))
    ref, ref_r = hand.spheres(g[:, :7], g[:, 7:])
    torch.testing.assert_close(centres, ref, atol=1e-6, rtol=0)
    torch.testing.assert_close(radii, ref_r.float())
    sub, _ = geo.spheres(coder.pose_of(g, g, g), subset=True)
    torch.testing.assert_close(sub, ref[:, geo.subset], atol=1e-6, rtol=0)
    assert set(geo.contact.tolist()) <= set(geo.subset.tolist())


def test_nearest_train_rows_retrieve_the_object_with_the_same_cloud():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(300, 3)).astype(np.float32), (rng.normal(size=(300, 3)) * 3 + 5).astype(np.float32)
    ts = SimpleNamespace(surface=torch.from_numpy(np.stack([a, b])), obs_of=torch.tensor([1, 0, 1, 0]))
    test = SimpleNamespace(surface=torch.from_numpy(np.stack([b[::-1].copy(), a])))  # b reordered, then a
    np.testing.assert_array_equal(learn.nearest_train_rows(ts, test, 3), [0, 2, 0, 1, 3, 1])


def test_bootstrap_over_objects():
    keys = [("a", 0.06), ("b", 0.06), ("c", 0.08)]
    same = {k: [True, False] for k in keys}
    assert learn.bootstrap(same, keys) == pytest.approx((0.5, 0.5))
    assert learn.bootstrap(same, keys, same) == pytest.approx((0.0, 0.0))
    # one object of five all successes, four all failures: the resampled rate is X / 5 with X ~
    # Binomial(5, 1/5); P(X = 0) = 0.33, P(X <= 2) = 0.942, P(X <= 3) = 0.993: the interval is [0, 3/5]
    five = [(c, 0.06) for c in "abcde"]
    mixed = {k: [k == five[0]] * 4 for k in five}
    lo, hi = learn.bootstrap(mixed, five)
    assert lo == pytest.approx(0.0) and hi == pytest.approx(0.6)
