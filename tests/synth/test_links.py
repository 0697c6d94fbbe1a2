"""A grasp type's extra contacts (palm, phalanges) against the kinematic tree and an exact SDF."""

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig
from datagen.synth.energies import contact_bounds
from datagen.synth.init import initial_poses
from datagen.tasks import InitConfig
from datagen.synth.links import contact_links, finger_chains, link_contacts

R = 0.05  # the ball's radius, m


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


@pytest.fixture(scope="module")
def ball():
    mesh = trimesh.creation.icosphere(4)  # unit radius: half its bounding-box diagonal is sqrt(3)
    return GraspTarget.from_mesh(mesh.apply_scale(1 / np.sqrt(3)), R * np.sqrt(3), "ball", grid_resolution=32)


def test_finger_chains_are_each_fingers_phalanges(hand):
    names = [[hand.link_names[i] for i in chain] for chain in finger_chains(hand)]
    assert dict(zip(hand.fingertip_names, names))["ff"] == ["robot0:ffproximal", "robot0:ffmiddle"]
    assert "robot0:lfmetacarpal" in names[hand.fingertip_names.index("lf")]
    assert all(hand.palm_link not in c for c in finger_chains(hand))
    tips = set(hand.fingertip_link_index.tolist())
    assert not tips & set(contact_links(hand))
    assert contact_links(hand, [1]) == finger_chains(hand)[1]


def test_nearest_link_points_match_the_exact_ball(hand, ball):
    """Each link's gap is the smallest of its spheres' exact gaps |c| - R - r (within the SDF
    grid's error), its point the exact nearest point R c / |c| and its normal -c / |c|."""
    links = torch.tensor([hand.palm_link] + contact_links(hand))
    init = InitConfig(distance_m=(0.0, 0.02), curl=0.5)  # palm facing the ball, fingers half flexed
    root, q = initial_poses(hand, [ball], torch.zeros(6, dtype=torch.long), init, torch.Generator().manual_seed(0))
    centres, radii = hand.spheres(root, hand.apply_couplings(q))
    lc = link_contacts(hand, [ball], torch.zeros(6, dtype=torch.long), centres, radii, links)
    c = centres.detach().numpy()
    exact = np.linalg.norm(c, axis=-1) - R - radii.numpy()  # (B, S)
    member = (hand.sphere_link_index[None, :] == links[:, None]).numpy()  # (L, S)
    want = np.where(member[None], exact[:, None, :], np.inf).min(-1)  # (B, L)
    near = want < 0.02  # the grid is exact near the surface (1-2 mm off at 3-4 cm)
    assert near.sum() > 10
    assert np.abs(lc.gap.numpy()[near] - want[near]).max() < 5e-4
    chosen = c[np.arange(6)[:, None], lc.sphere.numpy()]
    ref = R * chosen / np.linalg.norm(chosen, axis=-1, keepdims=True)
    assert np.abs(lc.points.numpy()[near] - ref[near]).max() < 1e-3
    cos = (lc.normals.numpy() * -chosen / np.linalg.norm(chosen, axis=-1, keepdims=True)).sum(-1)
    assert cos[near].min() > 0.99


def test_contact_bounds_fall_from_touching_to_the_activation_distance(hand):
    cfg = SynthConfig(link_activation_m=0.01).for_hand(hand)
    m = cfg.sphere_margin_m
    gap = torch.tensor([-0.003, -m, -m + 0.005, -m + 0.01, 0.05], dtype=torch.float64)
    assert torch.allclose(contact_bounds(gap, cfg), torch.tensor([1.0, 1.0, 0.5, 0.0, 0.0], dtype=torch.float64))


@pytest.mark.parametrize("layout", ["one target", "stacked", "mixed grids"])
def test_link_choice_is_the_nearest_sphere_by_each_targets_grid(hand, ball, layout):
    """Each link's chosen sphere and gap are the smallest of its spheres' gaps by each pose's own
    target (`GraspTarget.approx_query` on that pose alone): one target, two stacked grids, and two
    grids of different resolutions in an interleaved order (the per-target loop)."""
    box = GraspTarget.from_mesh(trimesh.creation.box((1.0, 0.6, 0.4)), 0.1, "box",
                                grid_resolution=24 if layout == "mixed grids" else 32)
    targets = [ball] if layout == "one target" else [ball, box]
    index = {"one target": torch.zeros(6, dtype=torch.long), "stacked": torch.tensor([0, 0, 0, 1, 1, 1]),
             "mixed grids": torch.tensor([1, 0, 0, 1, 0, 1])}[layout]
    links = torch.tensor([hand.palm_link] + contact_links(hand))
    init = InitConfig(distance_m=(0.0, 0.02), curl=0.5)
    root, q = initial_poses(hand, targets, index, init, torch.Generator().manual_seed(1))
    centres, radii = hand.spheres(root, hand.apply_couplings(q))
    lc = link_contacts(hand, targets, index, centres, radii, links)
    member = hand.sphere_link_index[None, :] == links[:, None]  # (L, S)
    for b in range(len(index)):
        gap = targets[int(index[b])].approx_query(centres[b].detach())[0] - radii  # (S,)
        want = torch.where(member, gap[None], torch.inf).min(-1)  # (L,) the least gap, its sphere
        assert torch.equal(lc.sphere[b], want.indices)
        assert torch.allclose(lc.gap[b], want.values, rtol=0, atol=1e-12)
