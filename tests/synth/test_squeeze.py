"""Pregrasp/squeeze construction: balanced grip forces and fingertip motion along the normals."""

import numpy as np
import pytest
import torch
from scipy.optimize import linprog

from datagen.hands import load_hand
from datagen.synth.energies import contact_sphere_index
from datagen.synth.squeeze import backtrack_pregrasp, balanced_forces, force_squeeze


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


def _pyramid_edges(ni: np.ndarray, edge_radius: float) -> list[np.ndarray]:
    """The 8 edges ``n + edge_radius * t`` of a contact's friction pyramid (t a unit tangent at
    multiples of 45 deg)."""
    t1 = np.cross(ni, [1.0, 0, 0] if abs(ni[0]) < 0.9 else [0, 1.0, 0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(ni, t1)
    return [ni + edge_radius * (np.cos(a) * t1 + np.sin(a) * t2) for a in 2 * np.pi * np.arange(8) / 8]


def _zero_wrench_feasible(p: np.ndarray, n: np.ndarray, edge_radius: float) -> bool:
    """LP over 8-edge pyramids: do forces with every normal part >= 1 and zero net wrench exist?

    Each pyramid's edges are ``n + edge_radius * t`` (t a unit tangent at multiples of 45 deg). For
    the friction cone ``|t| <= mu lam``: ``edge_radius = mu`` is the inscribed pyramid (edges on
    the cone), ``mu / cos(pi/8)`` the circumscribed one (faces tangent to the cone)."""
    F = len(p)
    cols = []
    for pi, ni in zip(p, n):
        cols += [np.concatenate([d, np.cross(pi - p.mean(0), d)]) for d in _pyramid_edges(ni, edge_radius)]
    A_eq = np.array(cols).T  # (6, 8F)
    A_ub = np.zeros((F, 8 * F))  # -(normal part of contact i) <= -1
    for i in range(F):
        A_ub[i, 8 * i:8 * i + 8] = -1.0
    res = linprog(np.zeros(8 * F), A_ub=A_ub, b_ub=-np.ones(F), A_eq=A_eq, b_eq=np.zeros(6), bounds=(0, None))
    return res.status == 0


def test_balanced_forces_cancel_for_force_closure_sets_and_not_otherwise():
    rng = np.random.default_rng(3)
    mu = 0.5
    for trial in range(12):
        p = rng.normal(size=(4, 3))
        p = 0.04 * p / np.linalg.norm(p, axis=1, keepdims=True)
        if trial % 3 == 0:
            p[:, 2] = np.abs(p[:, 2])  # one hemisphere only: often no balancing forces
        n = -p / np.linalg.norm(p, axis=1, keepdims=True)
        f = balanced_forces(torch.tensor(p[None]), torch.tensor(n[None]), mu)[0].numpy()
        lam = (f * n).sum(-1)
        tang = np.linalg.norm(f - lam[:, None] * n, axis=1)
        assert (lam >= 1 - 1e-9).all() and (tang <= mu * lam + 1e-9).all()  # inside the cones
        r = (p - p.mean(0)) / np.linalg.norm(p - p.mean(0), axis=1).mean()
        residual = np.linalg.norm(np.concatenate([f.sum(0), np.cross(r, f).sum(0)]))
        if _zero_wrench_feasible(p, n, 0.95 * mu):  # feasible with 5% of the friction to spare
            assert residual < 1e-2, (trial, residual)
        elif _zero_wrench_feasible(p, n, mu):  # inscribed pyramid feasible -> cone feasible, but only just:
            # projected gradient converges slowly there, so the default 300 iterations may stop short
            f = balanced_forces(torch.tensor(p[None]), torch.tensor(n[None]), mu, iters=5000)[0].numpy()
            residual = np.linalg.norm(np.concatenate([f.sum(0), np.cross(r, f).sum(0)]))
            assert residual < 1e-6, (trial, residual)
        elif not _zero_wrench_feasible(p, n, mu / np.cos(np.pi / 8)):  # circumscribed infeasible -> cone infeasible
            assert residual > 1e-3, (trial, residual)


def test_antipodal_pair_gets_opposing_normal_forces():
    p = torch.tensor([[[0.03, 0.0, 0.0], [-0.03, 0.0, 0.0]]], dtype=torch.float64)
    f = balanced_forces(p, -p / 0.03, 0.5)
    assert torch.allclose(f, torch.tensor([[[-1.0, 0, 0], [1.0, 0, 0]]], dtype=torch.float64), atol=1e-9)


def _tips(hand, root, joints, spheres):
    centres, _ = hand.spheres(root, joints)
    return centres[:, spheres]


def test_force_squeeze_is_the_statics_of_position_actuators(hand):
    # squeeze - grasp = J^T f / kp: check with finite differences of MuJoCo-independent FK,
    # i.e. that joint torques kp (squeeze - grasp) do the virtual work of forces f on the tips
    torch.manual_seed(1)
    B = 3
    root = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=torch.float64).expand(B, 7)
    hand64 = load_hand("shadow", dtype=torch.float64)
    mid = 0.5 * (hand64.joint_lower + hand64.joint_upper)
    joints = hand64.apply_couplings(mid + 0.1 * (torch.rand(B, hand64.num_joints, dtype=torch.float64) - 0.5))
    spheres = contact_sphere_index(hand64)
    tips = _tips(hand64, root, joints, spheres)
    normals = torch.nn.functional.normalize(tips.mean(1, keepdim=True) - tips, dim=-1)
    movable = torch.ones(hand64.num_joints, dtype=torch.bool)
    kp, force = 5.0, 3.0
    pre, sq = force_squeeze(hand64, root, joints, spheres, tips, normals, 0.5, kp, force, 0.0, movable)
    f = balanced_forces(tips, normals, 0.5)
    f = f * (force / f.norm(dim=-1).amax(-1))[:, None, None]
    tau = kp * (sq - joints)
    followers = {c[0] for c in hand64._couple}
    checked = 0
    for b in range(B):
        for j in set(range(hand64.num_joints)) - followers:
            lo, hi = float(hand64.joint_lower[j]), float(hand64.joint_upper[j])
            if not lo < float(sq[b, j]) < hi:
                continue  # the squeeze was clipped at a limit
            dq = torch.zeros_like(joints[b:b + 1])
            dq[0, j] = 1e-6  # a virtual displacement of independent joint j (followers follow)
            x1 = _tips(hand64, root[b:b + 1], hand64.apply_couplings(joints[b:b + 1] + dq), spheres)
            work = float(((x1 - tips[b:b + 1]) * f[b:b + 1]).sum() / 1e-6)  # generalized force of f on joint j
            assert abs(work - float(tau[b, j])) < 1e-4 + 1e-3 * abs(work), (b, j, work, float(tau[b, j]))
            checked += 1
    assert checked > 10
    assert torch.allclose(pre, hand64.apply_couplings(2 * joints - sq))


def test_force_squeeze_adds_no_force_when_the_contacts_all_push_one_way(hand):
    # fingertips under a plate, every inward normal +z: no forces cancel, so a squeeze would only
    # push a free object away; it reduces to the gap-closing motion (force 0). The same fingertips
    # with normals towards their centroid (a grip) get the full squeeze.
    B = 2
    root = torch.tensor([0, 0, 0, 1.0, 0, 0, 0]).expand(B, 7)
    joints = hand.apply_couplings((0.5 * (hand.joint_lower + hand.joint_upper)).expand(B, -1))
    spheres = contact_sphere_index(hand)[:3]
    tips = _tips(hand, root, joints, spheres)
    movable = torch.ones(hand.num_joints, dtype=torch.bool)
    up = torch.tensor([0, 0, 1.0]).expand(B, 3, 3)
    args = (hand, root, joints, spheres, tips)
    _, sq_up = force_squeeze(*args, up, 0.5, 5.0, 10.0, 0.002, movable)
    _, sq_gap = force_squeeze(*args, up, 0.5, 5.0, 0.0, 0.002, movable)
    assert torch.allclose(sq_up, sq_gap, atol=1e-6)
    grip = torch.nn.functional.normalize(tips.mean(1, keepdim=True) - tips, dim=-1)
    _, sq_grip = force_squeeze(*args, grip, 0.5, 5.0, 10.0, 0.002, movable)
    _, sq_grip0 = force_squeeze(*args, grip, 0.5, 5.0, 0.0, 0.002, movable)
    assert (sq_grip - sq_grip0).abs().amax() > 0.05  # 10 N at kp 5 N m/rad: tenths of a radian


def test_backtrack_pregrasp_halves_the_opening_until_no_deeper_than_the_grasp(hand):
    # a hand-computed case: the "object" is entered once joint k opens past 30% of the step
    k = 3
    grasp = hand.apply_couplings((0.5 * (hand.joint_lower + hand.joint_upper)).expand(3, -1).clone())
    step = torch.zeros_like(grasp)
    step[:, k] = torch.tensor([0.1, 0.1, 0.0]) * torch.sign(hand.joint_upper[k] - grasp[0, k])
    pre = grasp + step
    blocked = torch.tensor([False, True, False])  # row 1: deep at any opening, however small

    def depth(j):
        opening = (j[:, k] - grasp[:, k]).abs()
        return torch.where(blocked, 0.01 * (opening > 0), (opening - 0.03).clamp_min(0.0))

    out = backtrack_pregrasp(hand, grasp, pre, depth, slack_m=5e-4, halvings=4)
    assert float((out[0, k] - grasp[0, k]).abs()) == pytest.approx(0.025, abs=1e-6)  # 1 -> 0.5 -> 0.25 of 0.1 rad
    assert torch.equal(out[1], grasp[1])  # never clear: the grasp itself
    assert torch.equal(out[2], pre[2])  # nothing to do


def test_balanced_forces_inactive_contacts_carry_nothing_and_optional_ones_may():
    mu = 0.5
    # two opposed fingertips (must grip, lam >= 1) and a third contact pushing the same way as the
    # first: active with lam >= 0 it may carry nothing (the pair already balances); inactive: zero
    p = torch.tensor([[[0.03, 0, 0], [-0.03, 0, 0], [0.03, 0.01, 0]]], dtype=torch.float64)
    n = torch.tensor([[[-1.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0]]], dtype=torch.float64)
    lo = torch.tensor([[1.0, 1.0, 0.0]], dtype=torch.float64)
    f = balanced_forces(p, n, mu, iters=2000, min_normal=lo)
    assert f.sum(1).norm() < 1e-6
    assert (f[0, :2] * n[0, :2]).sum(-1).min() >= 1 - 1e-9
    f_off = balanced_forces(p, n, mu, iters=2000, active=torch.tensor([[True, True, False]]))
    assert f_off[0, 2].abs().max() == 0
    assert f_off.sum(1).norm() < 1e-6
    # a lone fingertip pushing +x is balanced only by an optional contact opposite it
    p2, n2 = p[:, [0, 1]], n[:, [0, 1]]
    f2 = balanced_forces(p2, n2, mu, iters=2000, min_normal=torch.tensor([[1.0, 0.0]], dtype=torch.float64))
    assert f2.sum(1).norm() < 1e-6 and float((f2[0, 1] * n2[0, 1]).sum()) >= 1 - 1e-6


def test_actuator_compliance_gives_the_wanted_generalized_forces():
    """The squeeze displacement dq = P tau / kp (tau: wanted generalized forces on the hand's
    independent joints) must make position actuators of stiffness kp, with the transmissions of
    the hand's MJCF (ctrl = A q), do the virtual work tau on every movable independent joint:
    for a virtual displacement of joint j through the hand's couplings (Shadow E3M5: one tendon
    actuator pulls J1 + J2, coupled 1:1), (A^T F) . dq_j = tau_j, F = kp A (squeeze - grasp).
    One actuator per joint (Allegro): dq = tau / kp exactly."""
    from datagen.synth.squeeze import actuator_compliance
    from datagen.synth.synthesize import finger_joint_mask

    kp = 5.0
    for name in ("shadow_e3m5", "allegro"):
        h = load_hand(name, dtype=torch.float64)
        movable = finger_joint_mask(h)
        followers = {c[0] for c in h._couple}
        A = torch.as_tensor(h.ctrl_matrix, dtype=torch.float64)
        q0 = h.apply_couplings(0.5 * (h.joint_lower + h.joint_upper))
        tau = torch.randn(h.num_joints, dtype=torch.float64, generator=torch.Generator().manual_seed(4))
        tau = tau * movable * torch.tensor([j not in followers for j in range(h.num_joints)])
        dq = actuator_compliance(h, movable) @ tau / kp
        F = kp * (A @ (h.apply_couplings(q0 + dq) - q0))
        checked = 0
        for j in range(h.num_joints):
            if not movable[j] or j in followers:
                continue
            e = torch.zeros_like(q0)
            e[j] = 1e-6
            work = float((A.T @ F) @ (h.apply_couplings(q0 + e) - q0)) / 1e-6
            assert abs(work - float(tau[j])) < 1e-6, (name, h.joint_names[j], work, float(tau[j]))
            checked += 1
        assert checked >= 12
        if name == "allegro":
            assert torch.allclose(dq, tau / kp)


def test_joint_mobility_is_the_velocity_of_the_joint_motion():
    from scipy.spatial.transform import Rotation

    from datagen.synth.squeeze import joint_mobility

    rng = np.random.default_rng(5)
    p = rng.normal(size=(2, 4, 3)) * 0.05
    axis = np.array([0.3, -0.4, 0.866])
    axis /= np.linalg.norm(axis)
    anchor = np.array([0.01, -0.02, 0.005])
    h = 1e-6  # finite difference of the motion itself: rotate about the axis through the anchor, or slide
    turned = Rotation.from_rotvec(h * axis).apply((p - anchor).reshape(-1, 3)).reshape(p.shape) + anchor
    u = joint_mobility(torch.tensor(p), "hinge", axis.tolist(), anchor.tolist()).numpy()
    np.testing.assert_allclose(u, (turned - p) / h, atol=1e-7)
    u = joint_mobility(torch.tensor(p), "slide", (2 * axis).tolist(), anchor.tolist()).numpy()
    np.testing.assert_allclose(u, np.broadcast_to(axis, p.shape), atol=1e-12)
    with pytest.raises(ValueError, match="hinge"):
        joint_mobility(torch.tensor(p), "free", axis.tolist(), anchor.tolist())


def _zero_joint_force_feasible(n: np.ndarray, u: np.ndarray, edge_radius: float) -> bool:
    """LP over 8-edge pyramids (as ``_zero_wrench_feasible``): do forces with every normal part
    >= 1 exist that do no work on the joint (``sum f_i . u_i = 0``)?"""
    F = len(n)
    cols = []
    for ni, ui in zip(n, u):
        cols += [d @ ui for d in _pyramid_edges(ni, edge_radius)]
    A_ub = np.zeros((F, 8 * F))
    for i in range(F):
        A_ub[i, 8 * i:8 * i + 8] = -1.0
    res = linprog(np.zeros(8 * F), A_ub=A_ub, b_ub=-np.ones(F), A_eq=np.array(cols)[None], b_eq=[0.0], bounds=(0, None))
    return res.status == 0


def test_mounted_balance_counts_only_the_force_along_the_joint():
    """Contacts on a knob (hinge) or a drawer bar (slide): the forces stay in their cones and do no
    work on the joint whenever an LP says such forces exist, and cannot where it says they cannot."""
    from datagen.synth.squeeze import joint_mobility

    rng = np.random.default_rng(11)
    mu, checked = 0.5, {"zero": 0, "nonzero": 0}
    for trial in range(24):
        kind = ("hinge", "slide")[trial % 2]
        ang = rng.uniform(0, 2 * np.pi, size=3)
        p = np.stack([0.02 * np.cos(ang), 0.02 * np.sin(ang), rng.uniform(0, 0.02, 3)], 1)
        u = joint_mobility(torch.tensor(p), kind, (0, 0, 1), (0, 0, 0)).numpy()
        # inward, tilted along the joint's motion by up to 60 deg; every third trial all one way
        tilt = rng.uniform(-1.7, 1.7, size=(3, 1))
        if trial % 3 == 0:
            tilt = np.abs(tilt) + 0.3
        n = -p * [1, 1, 0] / 0.02 + tilt * u / np.linalg.norm(u, axis=1, keepdims=True)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        f = balanced_forces(torch.tensor(p[None]), torch.tensor(n[None]), mu, iters=3000,
                            mobility=torch.tensor(u[None]))[0].numpy()
        lam = (f * n).sum(-1)
        tang = np.linalg.norm(f - lam[:, None] * n, axis=1)
        assert (lam >= 1 - 1e-9).all() and (tang <= mu * lam + 1e-9).all()
        work = abs((f * u).sum()) / np.linalg.norm(u, axis=1).mean() / np.linalg.norm(f, axis=1).sum()
        if _zero_joint_force_feasible(n, u, 0.95 * mu):
            assert work < 1e-3, (trial, work)
            checked["zero"] += 1
        elif not _zero_joint_force_feasible(n, u, mu / np.cos(np.pi / 8)):
            assert work > 1e-3, (trial, work)
            checked["nonzero"] += 1
    assert min(checked.values()) >= 3, checked  # both cases were exercised


def test_grip_forces_on_a_mounted_knob_grip_with_the_full_force():
    """Two fingertips on a knob 60 deg apart, pushing at its axis: on a free object their forces
    cannot cancel (tilted apart inside their friction cones they are still 113 deg apart, so at
    most 1 - cos(56.6 deg) = 45% of the grip is internal) and the squeeze is scaled down; on the knob's hinge they do
    no work on the joint (its bearing takes the net force), so the squeeze grips with force_n."""
    from datagen.synth.squeeze import grip_forces, joint_mobility

    a = np.radians([0.0, 60.0])
    p = torch.tensor(np.stack([0.02 * np.cos(a), 0.02 * np.sin(a), [0.01, 0.01]], 1)[None])
    n = -p * torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64) / 0.02
    u = joint_mobility(p, "hinge", (0, 0, 1), (0, 0, 0))
    hinge = ("hinge", (0, 0, 1), (0, 0, 0))
    free = grip_forces(p, n, 0.5, 10.0)
    mounted = grip_forces(p, n, 0.5, 10.0, mount=(*hinge, torch.tensor([True])))
    assert free.norm(dim=-1).max() < 4.6
    np.testing.assert_allclose(mounted.norm(dim=-1).max().item(), 10.0, rtol=1e-6)
    assert abs(float((mounted * u).sum())) < 1e-6 * 10.0  # no torque about the hinge
    same = grip_forces(p, n, 0.5, 10.0, mount=(*hinge, torch.tensor([False])))
    torch.testing.assert_close(same, free)  # samples not on the mounted object: the free rule
    both = grip_forces(p.expand(2, -1, -1), n.expand(2, -1, -1), 0.5, 10.0, mount=(*hinge, torch.tensor([False, True])))
    torch.testing.assert_close(both, torch.cat([free, mounted]))  # a mixed batch, row by row


def test_point_jacobian_matches_finite_differences_of_the_carried_points(hand):
    """d(point)/d(joints) of points rigidly carried by phalanges and the palm (a power grasp's
    squeeze) against central differences of the hand's forward kinematics."""
    from datagen.synth.squeeze import point_jacobian

    g = torch.Generator().manual_seed(2)
    B = 2
    root = torch.tensor([[0.0, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0]], dtype=hand.dtype).expand(B, -1)
    q = hand.apply_couplings(hand.joint_lower + (hand.joint_upper - hand.joint_lower)
                             * torch.rand(B, hand.num_joints, generator=g, dtype=hand.dtype))
    links = torch.tensor([[hand.palm_link, 3, 8], [5, hand.palm_link, 12]])
    offsets = 0.01 * torch.randn(B, 3, 3, generator=g, dtype=hand.dtype)
    T = hand.link_transforms(root, q)
    rows = torch.arange(B)[:, None]
    Tl = T[rows, links]
    points = Tl[..., :3, 3] + offsets  # world points near each link's origin
    local = (Tl[..., :3, :3].transpose(-1, -2) @ offsets[..., None]).squeeze(-1)

    def carried(qq):
        Ti = hand.link_transforms(root, hand.apply_couplings(qq))[rows, links]
        return ((Ti[..., :3, :3] @ local[..., None]).squeeze(-1) + Ti[..., :3, 3]).reshape(B, -1)

    J = point_jacobian(hand, root, q, links, points)
    h = 1e-3  # float32 kinematics: central differences good to ~1e-5 m/rad
    fd = torch.stack([(carried(q + h * e) - carried(q - h * e)) / (2 * h)
                      for e in torch.eye(hand.num_joints, dtype=hand.dtype)], -1)
    assert J.shape == (B, 9, hand.num_joints)
    assert torch.allclose(J, fd, atol=1e-4)
    assert J.abs().max() > 0.01
