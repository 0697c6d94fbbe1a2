"""The self-collision energy's broad phase skips only pairs that cannot overlap."""

import pytest
import torch

from datagen.hands import load_hand
from datagen.synth.energies import self_overlap_energy


@pytest.mark.parametrize("name", ["shadow", "allegro", "leap"])
def test_self_overlap_energy_equals_the_all_pairs_sum(name):
    """Against the all-pairs sum of squared sphere overlaps (the oracle), value and gradient,
    on poses from open to strongly flexed (so that some poses do self-collide)."""
    try:
        hand = load_hand(name)
    except Exception as exc:  # noqa: BLE001 - optional hands (make hands)
        pytest.skip(f"hand {name} not available: {exc}")
    g = torch.Generator().manual_seed(0)
    frac = torch.rand(6, hand.num_joints, generator=g) * torch.linspace(0.0, 1.0, 6)[:, None]
    joints = hand.apply_couplings(hand.joint_lower + frac * (hand.joint_upper - hand.joint_lower))
    joints = joints.double().requires_grad_(True)
    hand = hand.to(dtype=torch.float64)
    root = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=torch.float64).expand(6, 7)
    c, r = hand.spheres(root, joints)
    fast = self_overlap_energy(hand, c, r)
    (g_fast,) = torch.autograd.grad(fast.sum(), joints, retain_graph=True)
    i, j = hand.self_collision_pairs[:, 0], hand.self_collision_pairs[:, 1]
    brute = torch.relu(r[i] + r[j] - (c[:, i] - c[:, j]).norm(dim=-1)).square().sum(-1)
    (g_brute,) = torch.autograd.grad(brute.sum(), joints)
    assert (brute > 0).any()
    assert torch.allclose(fast, brute, rtol=1e-12, atol=1e-15)
    assert torch.allclose(g_fast, g_brute, rtol=1e-9, atol=1e-12)
