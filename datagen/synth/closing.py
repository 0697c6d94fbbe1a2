"""Close the fingers until they touch: the pre-shape of a power grasp, sized to the object.

A power grasp wraps the fingers round the object, and gradient descent from an open hand does not
find a wrap: the fingertips land on the near side and stay there (benchmarks/results/quality.md,
issue 41). A person, and the classic grasp planners' "auto-grasp", close the hand instead: with the
palm at the object, each finger flexes joint by joint, from the palm outwards, until a link it moves
touches the object; then the next joint goes on. :func:`close_until_contact` does that for a batch
of start poses, in ``steps`` increments per joint, so the fingers end round the object's own
surface at every size (a 6 cm ball curls them tight, a 20 cm one leaves them open).

Which joints flex, and which way, is found from the forward kinematics (:func:`flexion_joints`),
so it holds for any hand. A link "touches" when one of its collision spheres, shrunk by the hand's
sphere margin, reaches into the object's SDF grid; a joint stops at its last increment that
sinks the finger no deeper than it was before the joint moved.
"""

from __future__ import annotations

import torch

from datagen.synth.penetration import sphere_penetration

__all__ = ["close_until_contact", "flexion_joints"]


def flexion_joints(hand, step_rad: float = 1e-3) -> list[list[tuple[int, float]]]:
    """Per fingertip (``hand.fingertip_names`` order): its flexion joints from the palm outwards,
    each ``(joint index, limit)`` with the limit that moves the fingertip out of the palm's face.
    A joint counts when it moves exactly one fingertip, mostly along the palm normal (abduction
    moves it sideways), and is not a coupling's follower (it moves with its leader)."""
    ident = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=hand.dtype, device=hand.device)
    q0 = hand.open_pose
    approach = hand.palm_frame(ident, q0).approach
    approach = approach / approach.norm()
    tips0 = hand.fingertip_points(ident, q0)
    dq = step_rad * torch.eye(hand.num_joints, dtype=hand.dtype, device=hand.device)
    motion = (hand.fingertip_points(ident, hand.apply_couplings(q0 + dq)) - tips0) / step_rad  # (J, F, 3)
    speed, along = motion.norm(dim=-1), (motion * approach).sum(-1)
    followers = {c[0] for c in hand._couple}
    out: list[list[tuple[int, float]]] = [[] for _ in range(len(hand.fingertip_names))]
    for j in range(hand.num_joints):  # MuJoCo's joint order is the tree's: parents first
        moved = speed[j] > 1e-3
        if j in followers or int(moved.sum()) != 1:
            continue
        f = int(moved.nonzero())
        if along[j, f].abs() < 0.5 * speed[j, f]:
            continue
        out[f].append((j, float(hand.joint_upper[j] if along[j, f] > 0 else hand.joint_lower[j])))
    return out


def _finger_spheres(hand) -> list[torch.Tensor]:
    """Per fingertip, its chain's collision spheres (phalanges and tip, not the palm)."""
    from datagen.synth.links import finger_chains

    out = []
    for f, chain in enumerate(finger_chains(hand)):
        links = torch.tensor(chain + [int(hand.fingertip_link_index[f])], device=hand.device)
        out.append((hand.sphere_link_index[:, None] == links[None]).any(-1).nonzero().squeeze(-1))
    return out


def close_until_contact(hand, targets, object_index: torch.Tensor, root: torch.Tensor, joints: torch.Tensor,
                        steps: int = 12, margin_m: float = 0.0) -> torch.Tensor:
    """``(B, J)`` joints: each finger of the start poses (root ``(B, 7)``, joints ``(B, J)``)
    closed joint by joint until it touches ``targets[object_index]`` (see the module docstring);
    ``margin_m``: how far a sphere may sink before it counts as touching."""
    flex, spheres = flexion_joints(hand), _finger_spheres(hand)
    q = joints.clone()
    reach = hand.sphere_radii - margin_m
    B = q.shape[0]

    def depth(qq):  # (B, F) deepest penetration of each finger's spheres
        centres, _ = hand.spheres(root, hand.apply_couplings(qq))
        pen = sphere_penetration(targets, object_index, centres, reach)
        return torch.stack([pen[:, s].amax(-1) if s.numel() else pen.new_zeros(B) for s in spheres], -1)

    with torch.no_grad():
        for level in range(max((len(x) for x in flex), default=0)):
            moving = [(f, *x[level]) for f, x in enumerate(flex) if len(x) > level]
            idx = torch.tensor([j for _, j, _ in moving], device=q.device)
            fidx = torch.tensor([f for f, _, _ in moving], device=q.device)
            start = q[:, idx].clone()  # (B, M)
            limit = torch.tensor([lim for _, _, lim in moving], dtype=q.dtype, device=q.device)
            before = depth(q)[:, fidx]  # (B, M)
            free = torch.ones_like(start, dtype=torch.bool)
            for s in range(1, steps + 1):
                trial = q.clone()
                trial[:, idx] = start + (limit - start) * (s / steps)
                ok = free & (depth(trial)[:, fidx] <= before + 1e-5)
                q[:, idx] = torch.where(ok, trial[:, idx], q[:, idx])
                free = ok
                if not bool(free.any()):
                    break
    return hand.apply_couplings(q)
