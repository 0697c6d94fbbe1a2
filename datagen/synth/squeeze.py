"""Pregrasp and squeeze poses: balanced grip forces along the contact normals.

A grasp is executed by position-controlled fingers: the hand closes from the pregrasp to the
grasp, then its actuator targets move on to the squeeze pose, and the gap between the squeeze
targets and where the object stops the fingers sets the grip forces (tau = kp dq).
:func:`force_squeeze` chooses the task fingertips' forces with the smallest net wrench within
their friction cones (:func:`balanced_forces`) and turns them into joint offsets through the
actuators' compliance; the pregrasp is the mirror image (``pregrasp = 2 grasp - squeeze``), so
the fingers open along the same directions the squeeze presses. On a mounted task object (a
hinge or a slide) only the net force along the joint's motion must cancel
(:func:`joint_mobility`): the bearing takes the rest. (Three other constructions, moving the
fingertips a fixed distance along the normals, opening every joint towards the open pose, and
balancing the whole hand's contacts, were measured and not adopted: benchmarks/results/squeeze.md;
their code is in git at 2ce0499.)

The fingertip motion is the damped least-squares solution ``dq = J^T (J J^T + lambda^2 I)^-1 e``
of the fingertips' positional Jacobian ``J (3F, J)`` (joints shared by several fingertips, e.g.
the wrist, are held fixed), ``e (3F,)`` the wanted fingertip displacements: a first-order step,
exact to O(distance^2).

Opening the fingertips along their normals can swing another link of the same finger into the
object (a hooked finger's proximal phalanx into a bag's strap): a simulated grasp starting there
is kicked off the hand before it closes. :func:`backtrack_pregrasp` pulls such a pregrasp back
towards the grasp until no collision sphere sinks deeper than at the grasp.
"""

from __future__ import annotations

import torch

__all__ = ["actuator_compliance", "backtrack_pregrasp", "balanced_forces", "force_squeeze", "grip_forces",
           "joint_mobility", "point_jacobian", "tip_jacobian"]


def tip_jacobian(hand, root_pose: torch.Tensor, joints: torch.Tensor, tip_spheres: torch.Tensor) -> torch.Tensor:
    """``(B, 3F, J)`` d(contact sphere centres)/d(joints), m/rad, through the joint couplings.

    root_pose ``(B, 7)``, joints ``(B, J)``, tip_spheres ``(F,)`` sphere indices.
    """
    B, J = joints.shape
    R = 3 * tip_spheres.shape[0]
    with torch.enable_grad():  # one pass over R copies of the batch: copy r carries output row r
        q = joints.detach().repeat(R, 1).requires_grad_(True)  # (R B, J)
        T = hand.link_transforms(root_pose.detach().repeat(R, 1), hand.apply_couplings(q))
        x = hand._apply(T, hand.sphere_link_index[tip_spheres], hand.sphere_centres_local[tip_spheres]).reshape(R, B, R)
        rows = torch.arange(R, device=joints.device)
        (g,) = torch.autograd.grad(x[rows, :, rows].sum(), q)
    return g.reshape(R, B, J).transpose(0, 1)


def _damped_step(J: torch.Tensor, e: torch.Tensor, damping_m: float) -> torch.Tensor:
    """``(B, J)`` damped least-squares joint step ``J^T (J J^T + lambda^2 I)^-1 e`` moving the
    points of Jacobian ``J (B, 3F, J)`` by ``e (B, F, 3)``."""
    eye = torch.eye(J.shape[1], dtype=J.dtype, device=J.device)
    return (J.transpose(1, 2) @ torch.linalg.solve(J @ J.transpose(1, 2) + damping_m ** 2 * eye,
                                                    e.reshape(e.shape[0], -1, 1))).squeeze(-1)


def _balance(f: torch.Tensor, unit_mobility: torch.Tensor | None = None) -> torch.Tensor:
    """``(B,)`` 1 - |sum f| / sum |f| of forces ``(B, C, 3)``: 1 a pure grip, 0 all pushing one way.
    With ``unit_mobility`` ``(B, C, 3)`` (a mounted object, :func:`_unit_mobility`): 1 - |sum f . u| /
    sum |f|, the share of the grip that does not drive the object along its joint."""
    net = f.sum(1).norm(dim=-1) if unit_mobility is None else (f * unit_mobility).sum((1, 2)).abs()
    return (1.0 - net / f.norm(dim=-1).sum(-1).clamp_min(1e-12)).clamp(0.0, 1.0)


def grip_forces(points: torch.Tensor, inward_normals: torch.Tensor, mu: float, force_n: float,
                mount: tuple | None = None, min_normal: torch.Tensor | None = None,
                active: torch.Tensor | None = None, scale_count: int | None = None) -> torch.Tensor:
    """``(B, C, 3)`` N: the :func:`balanced_forces` of each sample, scaled so that the largest is
    ``force_n`` times the set's balance (:func:`_balance`). ``mount`` ``(kind, axis, anchor_m,
    mounted (B,) bool)``: the samples on a mounted object balance only the force along its joint
    (:func:`joint_mobility`; None: every sample is free). ``min_normal`` / ``active`` ``(B, C)``:
    as :func:`balanced_forces`; ``scale_count``: only the first that many contacts (the
    fingertips) set the scale (None: all)."""
    mounted = torch.zeros(points.shape[0], dtype=torch.bool, device=points.device) if mount is None else mount[3]
    on = points.new_ones(points.shape[:2]) if active is None else active.to(points.dtype)
    f = torch.empty_like(points)
    balance = points.new_empty(points.shape[0])
    for rows, joint in ((~mounted).nonzero().squeeze(-1), None), (mounted.nonzero().squeeze(-1), mount):
        if rows.numel() == 0:
            continue
        u = None if joint is None else joint_mobility(points[rows], *joint[:3])
        f[rows] = balanced_forces(points[rows], inward_normals[rows], mu, mobility=u,
                                  min_normal=None if min_normal is None else min_normal[rows],
                                  active=None if active is None else active[rows])
        balance[rows] = _balance(f[rows], None if u is None else _unit_mobility(u, on[rows]))
    largest = f[:, :scale_count].norm(dim=-1).amax(-1) if scale_count else f.norm(dim=-1).amax(-1)
    return f * (force_n * balance / largest.clamp_min(1e-9))[:, None, None]


def _grip(hand, joints, J_force, f, J_tips, inward_normals, movable, kp, approach_m, damping_m):
    """``(pregrasp, squeeze)``: the squeeze is the grasp plus the joint displacement whose
    actuators exert ``J_force^T f`` (:func:`actuator_compliance`) plus the fingertips' motion
    ``approach_m`` along their normals; the pregrasp is its mirror image about the grasp."""
    tau = (J_force.transpose(1, 2) @ f.reshape(f.shape[0], -1, 1)).squeeze(-1)
    dq_force = tau @ actuator_compliance(hand, movable).T / kp
    dq_gap = _damped_step(J_tips, approach_m * inward_normals, damping_m)
    squeeze = hand.apply_couplings(joints + dq_force + dq_gap)
    return hand.apply_couplings(2 * joints - squeeze), squeeze


def joint_mobility(points: torch.Tensor, kind: str, axis, anchor_m) -> torch.Tensor:
    """``(..., C, 3)``: the velocity of each contact point ``(..., C, 3)`` m of a mounted object
    moving on its joint at unit rate: ``axis`` for a ``slide`` (m/m), ``axis x (p - anchor)`` for a
    ``hinge`` (m/rad; ``anchor_m`` a point of the axis, metres, object frame). A contact force
    ``f_i`` does work ``f_i . u_i`` on the joint: ``sum_i f_i . u_i`` is the generalized force that
    moves the object; everything else the mount takes."""
    a = torch.as_tensor(axis, dtype=points.dtype, device=points.device)
    a = a / a.norm()
    if kind == "slide":
        return a.expand_as(points).clone()
    if kind == "hinge":
        o = torch.as_tensor(anchor_m, dtype=points.dtype, device=points.device)
        return torch.linalg.cross(a.expand_as(points), points - o)
    raise ValueError(f"joint_mobility: a mounted joint is 'hinge' or 'slide', got {kind!r}")


def balanced_forces(points: torch.Tensor, inward_normals: torch.Tensor, mu: float, iters: int = 300,
                    min_normal: torch.Tensor | None = None, active: torch.Tensor | None = None,
                    mobility: torch.Tensor | None = None) -> torch.Tensor:
    """``(B, C, 3)`` contact forces with the smallest net wrench, each in its friction cone.

    ``f_i = lam_i n_i + t_i`` with ``lam_i >= min_normal_i`` (default 1: every contact grips),
    ``t_i . n_i = 0``, ``|t_i| <= mu lam_i``, minimizing ``|sum f_i|^2 + |sum (p_i - c) x f_i|^2 / L^2``
    (``c`` the centroid of the active contacts, ``L`` their mean distance from it, as in the contact
    position normalization) by projected gradient descent (FISTA). A force-closure set reaches zero
    net wrench (internal forces only); the residual of any other set is as small as the cones
    allow. points ``(B, C, 3)`` m; min_normal ``(B, C)``; active ``(B, C)`` bool (inactive contacts
    carry no force).

    ``mobility`` ``(B, C, 3)`` (:func:`joint_mobility`): the object is mounted on a one-dof joint,
    and only the net force along its motion counts, ``(sum_i f_i . u_i / U)^2`` with ``U`` the
    active contacts' mean ``|u_i|``: the mount (a hinge's bearing, a drawer's runners) takes the
    rest of the net wrench, so forces need not cancel across the joint's constrained directions.
    """
    B, C = points.shape[:2]
    lo = points.new_ones(B, C) if min_normal is None else min_normal.to(points.dtype)
    on = points.new_ones(B, C) if active is None else active.to(points.dtype)
    lo = (lo * on)[..., None]
    w = on[..., None]
    n = inward_normals / inward_normals.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    if mobility is not None:
        u = _unit_mobility(mobility, on)
        step = 1.0 / (2 * u.square().sum((1, 2)).clamp_min(1e-9))[:, None, None]
        return _fista(n, lo, w, mu, iters, step, lambda y: 2 * (y * u).sum((1, 2))[:, None, None] * u)
    c = (points * w).sum(1, keepdim=True) / w.sum(1, keepdim=True).clamp_min(1.0)
    r = (points - c) * w
    r = r / ((r.norm(dim=-1).sum(1) / on.sum(1).clamp_min(1.0))[:, None, None]).clamp_min(1e-9)

    def grad_fn(y):  # d/df_i of the residual
        force = y.sum(1, keepdim=True)  # (B, 1, 3)
        torque = torch.linalg.cross(r, y).sum(1, keepdim=True)
        return 2 * (force + torch.linalg.cross(torque.expand_as(r), r))

    # Lipschitz constant of the residual's gradient: 2 |A|^2 <= 2 C (1 + max |r|^2)
    step = 1.0 / (2 * on.sum(1).clamp_min(1.0) * (1 + r.square().sum(-1).amax(-1)))[:, None, None]
    return _fista(n, lo, w, mu, iters, step, grad_fn)


def _unit_mobility(mobility: torch.Tensor, on: torch.Tensor) -> torch.Tensor:
    """``(B, C, 3)`` contact mobilities over the active contacts' mean ``|u_i|`` (0 where inactive;
    all 0 where every active contact is on a hinge's axis: no force can turn it)."""
    u = mobility * on[..., None]
    mean = u.norm(dim=-1).sum(1) / on.sum(1).clamp_min(1.0)  # (B,)
    return torch.where(mean[:, None, None] > 1e-12, u / mean.clamp_min(1e-12)[:, None, None], torch.zeros_like(u))


def _fista(n, lo, w, mu, iters, step, grad_fn):
    """Accelerated projected gradient of a residual with gradient ``grad_fn`` over the contact
    forces' cones ``{lam >= lo, |t| <= mu lam}`` (zero where ``w`` is 0); see :func:`balanced_forces`."""

    def project(f):  # Euclidean projection onto {lam >= lo, |t| <= mu lam}, zero where inactive
        lam = (f * n).sum(-1, keepdim=True)
        t = f - lam * n
        s = t.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        lam_k = ((lam + mu * s) / (1 + mu * mu)).clamp_min(0.0)  # onto the cone (outside it)
        inside = s <= mu * lam
        lam_c = torch.where(inside, lam, lam_k)
        t_c = torch.where(inside, t, t * (mu * lam_k / s))
        low = lam_c < lo  # the cone's projection violates lam >= lo: project onto the disc lam = lo
        t_c = torch.where(low, t * (mu * lo / s).clamp_max(1.0), t_c)
        return (torch.where(low, lo, lam_c) * n + t_c) * w

    f = y = n * lo.clamp_min(1e-3) * w
    for k in range(iters):  # accelerated projected gradient (FISTA)
        f_next = project(y - step * grad_fn(y))
        y = f_next + (k / (k + 3)) * (f_next - f)
        f = f_next
    return f


def actuator_compliance(hand, movable: torch.Tensor) -> torch.Tensor:
    """``(J, J)`` P such that the squeeze displacement ``dq = P tau / kp`` makes the hand's position
    actuators (stiffness ``kp`` each, transmissions ``ctrl = A q``, A = ``hand.ctrl_matrix``)
    exert on the blocked hand the generalized forces closest to ``tau`` (least squares), in the
    coordinates of the hand's independent joints (followers of a coupling move with their
    leaders). ``P = pinv(C^T A^T A C)`` over the ``movable`` joints, C the couplings' Jacobian.

    One actuator per joint (gear 1): P = I, ``dq = tau / kp``. A tendon actuator driving two
    joints (Shadow E3M5's J1 + J2 of each finger) pulls both with the same force
    ``kp (dq_1 + dq_2)``: setting each joint's ``dq_i = tau_i / kp`` as if it had its own actuator
    doubles the force; P splits ``(tau_1 + tau_2) / 2`` evenly instead."""
    J = hand.num_joints
    dt, dev = hand.joint_lower.dtype, hand.joint_lower.device
    C = torch.eye(J, dtype=torch.float64, device=dev)
    for follower, leader, ratio, _offset in hand._couple:
        C[follower, follower] = 0.0
        C[follower, leader] = ratio
    A = torch.as_tensor(hand.ctrl_matrix, dtype=torch.float64, device=dev)
    AC = A @ C
    M = AC.T @ AC
    m = movable.to(dev)
    M = M * (m[:, None] & m[None, :])
    return torch.linalg.pinv(M, hermitian=True).to(dt)


def force_squeeze(hand, root_pose: torch.Tensor, joints: torch.Tensor, tip_spheres: torch.Tensor,
                  points: torch.Tensor, inward_normals: torch.Tensor, mu: float, kp: float, force_n: float,
                  approach_m: float, movable: torch.Tensor, damping_m: float = 0.01,
                  mount: tuple | None = None, extra: tuple | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """``(pregrasp, squeeze)`` joints ``(B, J)`` whose squeeze makes balanced grip forces.

    Position actuators of stiffness ``kp`` (N m/rad) pushed ``dq`` past a blocked pose exert
    ``tau = kp dq = J^T f``: the squeeze ``grasp + J^T f / kp`` presses each fingertip on the
    object with the :func:`balanced_forces` ``f``, scaled so the largest is ``force_n`` newtons
    times the set's balance ``1 - |sum f| / sum |f|`` (1: the forces cancel, a pure grip; 0: they
    all push one way, as fingers under a plate or hooked in a strap, and a squeeze would only
    push the object out of the hand, so none is added), plus the fingertip motion that closes
    ``approach_m`` along the normal (the gap between the collision spheres and the hand's real
    geometry). The pregrasp is the mirror image
    (``pregrasp = 2 grasp - squeeze``), so the fingers open along the same directions.
    ``mount``: the joint of a mounted object and the samples on it, whose balance counts only the
    force along that joint (:func:`grip_forces`).

    ``extra`` ``(points (B, L, 3), inward normals (B, L, 3), links (B, L), touching (B, L))``: a
    power grasp's other contacts (the palm centre, the phalanges' nearest points; ``links`` the
    hand link carrying each). Those touching take part in the balance with a normal force >= 0
    (they may carry load, need not), so the fingertips' forces no longer have to cancel among
    themselves: the palm (no movable joint) only reacts, and the joint torques include the
    phalanges' share, ``tau = sum_c J_c^T f_c``. The scale is still set by the largest fingertip
    force.
    """
    mm = movable.to(joints.dtype)
    Jt = tip_jacobian(hand, root_pose, joints, tip_spheres) * mm  # (B, 3F, J)
    if extra is None:
        f = grip_forces(points, inward_normals, mu, force_n, mount=mount)
        return _grip(hand, joints, Jt, f, Jt, inward_normals, movable, kp, approach_m, damping_m)
    lp, ln, links, touching = extra
    B, F = points.shape[:2]
    P, N = torch.cat([points, lp], 1), torch.cat([inward_normals, ln], 1)
    active = torch.cat([torch.ones(B, F, dtype=torch.bool, device=P.device), touching], 1)
    lo = torch.cat([P.new_ones(B, F), P.new_zeros(touching.shape)], 1)
    f = grip_forces(P, N, mu, force_n, mount=mount, min_normal=lo, active=active, scale_count=F)
    tip_links = hand.sphere_link_index[tip_spheres].expand(B, F)
    Jc = point_jacobian(hand, root_pose, joints, torch.cat([tip_links, links], 1), P) * mm  # (B, 3C, J)
    return _grip(hand, joints, Jc, f, Jt, inward_normals, movable, kp, approach_m, damping_m)


def point_jacobian(hand, root_pose: torch.Tensor, joints: torch.Tensor, links: torch.Tensor,
                   points: torch.Tensor) -> torch.Tensor:
    """``(B, 3C, J)`` d(points)/d(joints), m/rad, through the joint couplings, of world points
    ``(B, C, 3)`` m rigidly carried by hand links ``links (B, C)`` (indices into the hand's links)."""
    B, J = joints.shape
    R = 3 * links.shape[1]
    rows = torch.arange(B, device=joints.device)[:, None]
    with torch.no_grad():
        Tl = hand.link_transforms(root_pose.detach(), hand.apply_couplings(joints.detach()))[rows, links]
        local = (Tl[..., :3, :3].transpose(-1, -2) @ (points - Tl[..., :3, 3])[..., None]).squeeze(-1)  # (B, C, 3)
    with torch.enable_grad():  # one pass over R copies of the batch: copy r carries output row r
        q = joints.detach().repeat(R, 1).requires_grad_(True)  # (R B, J)
        T = hand.link_transforms(root_pose.detach().repeat(R, 1), hand.apply_couplings(q)).reshape(R, B, -1, 4, 4)
        Ti = T[:, rows, links]  # (R, B, C, 4, 4)
        x = ((Ti[..., :3, :3] @ local[None, ..., None]).squeeze(-1) + Ti[..., :3, 3]).reshape(R, B, R)
        r = torch.arange(R, device=joints.device)
        (g,) = torch.autograd.grad(x[r, :, r].sum(), q)
    return g.reshape(R, B, J).transpose(0, 1)


def backtrack_pregrasp(hand, grasp: torch.Tensor, pregrasp: torch.Tensor, depth_fn, slack_m: float = 5e-4,
                       halvings: int = 4) -> torch.Tensor:
    """``(B, J)`` pregrasp joints no deeper in the object than the grasp.

    ``depth_fn(joints (B, J)) -> (B,)`` is the deepest collision-sphere penetration (m) of the
    hand at those joints (root fixed). On rows where the pregrasp is deeper than the grasp by
    more than ``slack_m``, the step ``pregrasp - grasp`` is halved, up to ``halvings`` times;
    rows still too deep get the grasp itself (the hand closes from there: no approach motion).
    """
    limit = depth_fn(grasp) + slack_m
    alpha = torch.ones(grasp.shape[0], 1, dtype=grasp.dtype, device=grasp.device)
    step = pregrasp - grasp
    for _ in range(halvings + 1):
        bad = depth_fn(hand.apply_couplings(grasp + alpha * step)) > limit
        if not bool(bad.any()):
            break
        alpha = torch.where(bad[:, None], alpha * 0.5, alpha)
    else:
        alpha = torch.where(bad[:, None], torch.zeros_like(alpha), alpha)
    return hand.apply_couplings(grasp + alpha * step)
