"""The reference learner's grasp vectors (examples/learn_grasps.py): encoding then decoding gives
back the three poses (scipy's rotations as the reference), and a hand-computed case."""

import importlib.util
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

_spec = importlib.util.spec_from_file_location("learn_grasps",
                                               Path(__file__).parents[1] / "examples" / "learn_grasps.py")
learn = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(learn)


def test_grasp_vectors_round_trip():
    rng = np.random.default_rng(0)
    lo, hi = np.array([-0.5, 0.0, 0.1]), np.array([0.5, 1.6, 1.2])
    n = 32
    rot = Rotation.random(n, random_state=1)
    root = np.concatenate([rng.uniform(-0.15, 0.15, (n, 3)), np.roll(rot.as_quat(), 1, axis=1)], 1)
    grasp = np.concatenate([root, rng.uniform(lo, hi, (n, 3))], 1)
    delta = rng.uniform(-0.2, 0.2, (n, 3))
    pre, squeeze = grasp.copy(), grasp.copy()
    pre[:, 7:] -= delta
    squeeze[:, 7:] += 0.5 * delta
    coder = learn.GraspCoder(lo, hi)
    v = coder.encode(*(torch.tensor(x, dtype=torch.float32) for x in (pre, grasp, squeeze)))
    assert v.shape == (n, 9 + 3 * 3)
    p2, g2, s2 = coder.decode(v)
    np.testing.assert_allclose(g2[:, :3], grasp[:, :3], atol=1e-6)
    assert np.all((Rotation.from_quat(np.roll(g2[:, 3:7], -1, axis=1)) * rot.inv()).magnitude() < 1e-5)
    for a, b in ((p2, pre), (g2, grasp), (s2, squeeze)):
        np.testing.assert_allclose(a[:, 7:], b[:, 7:], atol=1e-5)
        np.testing.assert_array_equal(a[:, :7], g2[:, :7])  # one root for the three poses


def test_grasp_vector_hand_case():
    # the identity hand at (0.05, 0, -0.1) m with its joints at the limits' midpoints: translation
    # in units of 10 cm, the matrix's first two columns, joints at 0, no offsets
    coder = learn.GraspCoder(np.array([0.0, -1.0]), np.array([1.0, 1.0]))
    g = torch.tensor([[0.05, 0.0, -0.1, 1.0, 0.0, 0.0, 0.0, 0.5, 0.0]])
    v = coder.encode(g, g, g)
    np.testing.assert_allclose(v.numpy(), [[0.5, 0, -1, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0]], atol=1e-6)
    # a decoded joint beyond its limit is clamped to it
    v[0, 9] = 3.0
    assert coder.decode(v)[1][0, 7] == 1.0


def test_turned_grasps_are_the_grasps_of_the_turned_object():
    # a grasp at (0.1, 0, 0) with the identity orientation, the object turned 90 deg about z:
    # the hand is at (0, 0.1, 0), turned the same way
    coder = learn.GraspCoder(np.array([0.0]), np.array([1.0]))
    g = torch.tensor([[0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5]])
    turn = torch.tensor([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    _, g2, _ = coder.decode(coder.encode(g, g, g, turn=turn))
    np.testing.assert_allclose(g2[0, :3], [0.0, 0.1, 0.0], atol=1e-6)
    c = np.sqrt(0.5)
    np.testing.assert_allclose(np.abs(g2[0, 3:7]), [c, 0, 0, c], atol=1e-6)
    R = learn.random_rotations(64, torch.Generator().manual_seed(0))
    np.testing.assert_allclose((R @ R.transpose(1, 2)).numpy(), np.broadcast_to(np.eye(3), (64, 3, 3)), atol=1e-5)
    assert torch.allclose(torch.linalg.det(R), torch.ones(64), atol=1e-5)


def test_nearest_train_grasps_retrieve_the_object_with_the_same_cloud():
    from types import SimpleNamespace

    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(300, 3)).astype(np.float32), (rng.normal(size=(300, 3)) * 3 + 5).astype(np.float32)
    ds = SimpleNamespace(observations=[{"points": torch.from_numpy(a)}, {"points": torch.from_numpy(b)}],
                         pairs=[(0, 1), (1, 0), (2, 1), (3, 0)])  # (grasp, observation): grasps 0, 2 are of b
    test = torch.from_numpy(np.stack([b[::-1].copy(), a]))  # b's cloud reordered, then a's
    np.testing.assert_array_equal(learn.nearest_train_grasps(ds, test, None, 3), [0, 2, 0, 1, 3, 1])
