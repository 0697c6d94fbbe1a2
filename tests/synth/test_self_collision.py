"""The self-collision energy's broad phase skips only pairs that cannot overlap."""

import pytest
import torch

from datagen.hands import load_hand
from datagen.synth.self_collision import self_overlap_energy


def _hand(name: str):
    """The hand, or the test skipped (Allegro and LEAP are optional: make hands)."""
    try:
        return load_hand(name)
    except Exception as exc:  # noqa: BLE001 - optional hands (make hands)
        pytest.skip(f"hand {name} not available: {exc}")


@pytest.mark.parametrize("name", ["shadow", "allegro", "leap"])
def test_self_overlap_energy_equals_the_all_pairs_sum(name):
    """Against the all-pairs sum of squared sphere overlaps (the oracle), value and gradient,
    on poses from open to strongly flexed (so that some poses do self-collide)."""
    hand = _hand(name)
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


@pytest.mark.parametrize("name", ["shadow", "allegro", "leap"])
def test_reused_pair_lists_equal_the_all_pairs_sum_along_a_walk(name):
    """Pair lists kept across calls (SelfPairList) against the all-pairs sum (the oracle) along a
    random walk of the joints and the root with steps of 0.1 to 8 mm-scale: small steps reuse the
    lists, large ones force new lists for some poses; the value must equal the oracle at every call
    and equal the list-free energy bit for bit (same pairs, same order)."""
    from datagen.synth.self_collision import SelfPairList

    hand = _hand(name)
    g = torch.Generator().manual_seed(1)
    B = 6
    lo, hi = hand.joint_lower, hand.joint_upper
    joints = lo + (hi - lo) * (0.3 + 0.4 * torch.rand(B, hand.num_joints, generator=g))
    root = torch.tensor([0.01, -0.02, 0.03, 1.0, 0, 0, 0]).repeat(B, 1)
    pairs = SelfPairList(hand, skin_m=0.004)
    i, j = hand.self_collision_pairs[:, 0], hand.self_collision_pairs[:, 1]
    for step in [0.001, 0.002, 0.0, 0.05, 0.001, 0.001, 0.08, 0.0005, 0.0005, 0.002]:
        joints = hand.apply_couplings((joints + step * torch.randn(joints.shape, generator=g)).clamp(lo, hi))
        root = root.clone()
        root[:, :3] += 0.01 * torch.randn(B, 3, generator=g)  # moving the whole hand never invalidates a list
        T = hand.link_transforms(root, joints)
        c, r = hand.spheres(root, joints, transforms=T)
        listed = self_overlap_energy(hand, c, r, pairs, T[:, hand.palm_link])
        fresh = self_overlap_energy(hand, c, r)
        brute = torch.relu(r[i] + r[j] - (c[:, i] - c[:, j]).norm(dim=-1)).square().sum(-1)
        assert torch.equal(listed, fresh)
        assert torch.allclose(listed, brute, rtol=1e-5, atol=1e-12)
    assert (brute > 0).any()
    assert 0 < pairs.rebuilt < 10 * B  # some calls reused lists, the large steps made new ones


def test_pair_list_starts_afresh_for_another_batch():
    from datagen.synth.self_collision import SelfPairList

    hand = load_hand("shadow")
    pairs = SelfPairList(hand)
    for B in (4, 2):
        joints = hand.apply_couplings(hand.joint_lower + 0.8 * (hand.joint_upper - hand.joint_lower)).expand(B, -1)
        root = torch.tensor([0, 0, 0, 1.0, 0, 0, 0]).expand(B, 7)
        T = hand.link_transforms(root, joints)
        c, r = hand.spheres(root, joints, transforms=T)
        assert torch.equal(self_overlap_energy(hand, c, r, pairs, T[:, hand.palm_link]), self_overlap_energy(hand, c, r))
    assert pairs.rebuilt == 6
    with pytest.raises(ValueError, match="skin_m"):
        SelfPairList(hand, skin_m=0.0)


def test_synthesis_is_the_same_with_and_without_reused_pair_lists():
    """The pair lists only skip work: a whole multi-start synthesis gives identical tensors."""
    import dataclasses

    import numpy as np
    import trimesh

    from datagen.synth import GraspTarget, SynthConfig, synthesize
    from datagen.tasks import load_task

    try:
        hand = load_hand("allegro")
    except Exception as exc:  # noqa: BLE001 - optional hands (make hands)
        pytest.skip(f"hand allegro not available: {exc}")
    mesh = trimesh.creation.box(extents=(0.6, 0.8, 1.0))
    mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))
    target = GraspTarget.from_mesh(mesh, 0.07, "box")
    cfg = SynthConfig(iters=40, seeds_per_grasp=2, seed_select_iter=20, seed=2)
    a = synthesize(hand, [target], load_task("force_closure"), cfg, 2)
    b = synthesize(hand, [target], load_task("force_closure"), dataclasses.replace(cfg, self_pair_skin_m=0.0), 2)
    assert torch.equal(a.grasp, b.grasp) and torch.equal(a.squeeze, b.squeeze)
    assert a.energies["self_penetration"].sum() >= 0


def test_merged_pair_lists_are_in_pose_then_pair_order():
    """Two lists in (pose, rank) order, each pose in one of them: the merge equals a full sort."""
    from datagen.synth.self_collision import _merge_by_pose

    g = torch.Generator().manual_seed(0)
    B = 9
    fresh = torch.rand(B, generator=g) < 0.5  # poses whose list is made anew
    lists = ([], [])
    for pose in range(B):
        pairs = torch.randperm(40, generator=g)[:int(torch.randint(0, 6, (1,), generator=g))].sort().values
        lists[int(fresh[pose])].append((torch.full_like(pairs, pose), pairs))
    a, b = [(torch.cat([r for r, _ in x]), torch.cat([p for _, p in x])) for x in lists]
    rows, pair = _merge_by_pose(a, b, B)
    order = torch.argsort(torch.cat([a[0], b[0]]) * 40 + torch.cat([a[1], b[1]]))
    assert torch.equal(rows, torch.cat([a[0], b[0]])[order]) and torch.equal(pair, torch.cat([a[1], b[1]])[order])
    assert a[0].numel() and b[0].numel()  # both lists had entries


@pytest.mark.parametrize("name", ["shadow", "allegro", "leap"])
def test_candidate_pairs_with_a_margin_per_pose_equal_the_brute_force_list(name):
    """The broad phase (cluster bounds; for Allegro and LEAP also the link-pair culling of the
    block distance matrices) against every pair's own gap: with a margin per pose (the pair
    lists' 4 mm skin or the 1 um of a list for one call), exactly the pairs within it, in
    (pose, cluster pair, pair) order."""
    from datagen.synth.self_collision import _cluster_bounds, candidate_pairs

    hand = _hand(name)
    g = torch.Generator().manual_seed(3)
    B = 8
    frac = 0.5 + 0.5 * torch.rand(B, hand.num_joints, generator=g)  # flexed: some pairs overlap
    joints = hand.apply_couplings(hand.joint_lower + frac * (hand.joint_upper - hand.joint_lower))
    root = torch.tensor([0.02, 0.0, -0.01, 1.0, 0, 0, 0]).expand(B, 7)
    c, r = hand.spheres(root, joints)
    margin = torch.where(torch.arange(B) % 2 == 0, 0.004, 1e-6).to(c.dtype)
    rows, pair = candidate_pairs(hand, c, r, margin)
    i, j = hand.self_collision_pairs[:, 0], hand.self_collision_pairs[:, 1]
    near = (c[:, i] - c[:, j]).norm(dim=-1) < r[i] + r[j] + margin[:, None]  # (B, P)
    b, p = near.nonzero(as_tuple=True)
    order = torch.argsort(b * i.numel() + _cluster_bounds(hand)["rank"][p])
    assert torch.equal(rows, b[order]) and torch.equal(pair, p[order])
    assert (rows % 2 == 0).any() and (rows % 2 == 1).any()  # both margins found pairs
    odd = int(rows[rows % 2 == 1][0])
    assert torch.equal(candidate_pairs(hand, c[odd:odd + 1], r, 1e-6)[1], pair[rows == odd])  # as a number


@pytest.mark.parametrize("name", ["allegro", "leap"])
def test_culled_blocks_find_the_groups_of_the_whole_blocks(name):
    """The CPU's link-culled blocks (`_block_groups`) and the whole blocks other devices use
    (`_dense_groups`): the same (pose, cluster pair) list, for a number and a margin per pose."""
    from datagen.synth.self_collision import _block_groups, _cluster_bounds, _dense_groups
    from datagen.scatter import index_add

    hand = _hand(name)
    g = torch.Generator().manual_seed(4)
    B = 12
    frac = torch.rand(B, hand.num_joints, generator=g)
    joints = hand.apply_couplings(hand.joint_lower + frac * (hand.joint_upper - hand.joint_lower))
    c, _ = hand.spheres(torch.tensor([0.0, 0.01, 0.0, 1.0, 0, 0, 0]).expand(B, 7), joints)
    t = _cluster_bounds(hand)
    centre = index_add(torch.zeros(B, t["count"].shape[0], 3), 1, t["cluster"], c) / t["count"][:, None].float()
    for margin in (0.004, torch.where(torch.arange(B) % 3 == 0, 0.004, 1e-6)[:, None].float()):
        culled, whole = _block_groups(t, centre, margin), _dense_groups(t, centre, margin)
        assert whole[0].numel() > 0
        assert torch.equal(culled[0], whole[0]) and torch.equal(culled[1], whole[1])


@pytest.mark.parametrize("name", ["shadow", "allegro", "leap"])
@pytest.mark.parametrize("probe", [True, False])
def test_sphere_probes_and_listed_pairs_find_the_brute_force_pairs(name, probe):
    """Both ways from cluster-pair hits to sphere pairs (the probes of each sphere against the
    other cluster's bound, `_probed_pairs`, and every pair of a hit, `_listed_pairs`), whichever
    the hand uses by default, against every pair's own gap (the oracle): exactly the pairs within
    the margin (0, 1 um, 4 mm, 2 cm), in (pose, cluster pair, pair) order, on random poses from
    open to fully flexed and moved off the origin."""
    from datagen.synth.self_collision import _cluster_bounds, candidate_pairs

    hand = _hand(name)
    t = _cluster_bounds(hand)
    default = t["probe"]
    g = torch.Generator().manual_seed(5)
    B = 10
    frac = torch.rand(B, hand.num_joints, generator=g) * torch.linspace(0.2, 1.0, B)[:, None]
    joints = hand.apply_couplings(hand.joint_lower + frac * (hand.joint_upper - hand.joint_lower))
    quat = torch.nn.functional.normalize(torch.randn(B, 4, generator=g), dim=-1)
    root = torch.cat([0.5 * torch.randn(B, 3, generator=g), quat], -1)
    c, r = hand.spheres(root, joints)
    i, j = hand.self_collision_pairs[:, 0], hand.self_collision_pairs[:, 1]
    gap = (c[:, i] - c[:, j]).norm(dim=-1) - (r[i] + r[j])  # (B, P), as the narrow phase compares
    rank = t["rank"]
    try:
        t["probe"] = probe
        per_pose = torch.tensor([0.0, 1e-6, 0.004, 0.02]).repeat(3)[:B]
        for margin in (0.0, 1e-6, 0.004, 0.02, per_pose):
            rows, pair = candidate_pairs(hand, c, r, margin)
            m = margin[:, None] if torch.is_tensor(margin) else margin
            near = (c[:, i] - c[:, j]).norm(dim=-1) < r[i] + r[j] + m
            b, p = near.nonzero(as_tuple=True)
            order = torch.argsort(b * i.numel() + rank[p])
            assert torch.equal(rows, b[order]) and torch.equal(pair, p[order]), margin
    finally:
        t["probe"] = default
    assert (gap < 0).any()  # some poses self-collide
    assert default == (name != "shadow")  # LEAP and Allegro probe by default, Shadow does not
