"""Bring the real fingertips onto the surface together before the pregrasp and squeeze are built.

The optimizer places collision *spheres*, which overshoot the fingertips' collision geometry (by
up to the sphere fit's overshoot, 2.6-2.8 mm along Shadow's pad normals) while the distance term
sinks them by only the hand's sphere margin. At a synthesized grasp the real fingertips therefore
stand off the object by ~0.4-2 mm, each by its own amount, and while MuJoCo closes the hand the
nearest one touches first and pushes a light free object (the task benchmark's key) away before
the others arrive (tasks.md, session 10).

:func:`touch_grasp` measures each task fingertip's real gap -- the smallest exact object distance
over points on its link's collision surface -- and moves every fingertip in along its contact
normal by that gap (damped least squares through the fingertip Jacobians, re-measured and
corrected over a few steps), so that all of them reach the surface at the end of the closing.
"""

from __future__ import annotations

import numpy as np
import torch

from datagen.hands.geometry import link_shapes, sample_link_surface
from datagen.synth.self_collision import farthest_point_seeds

__all__ = ["TIP_SURFACE_POINTS", "TOUCH_STEPS", "real_tip_gaps", "tip_surface_points", "touch_grasp"]

TIP_SURFACE_POINTS = 1024  #: points per fingertip link (farthest-point subsample of 20k surface samples, seeded)
TOUCH_STEPS = 3  #: re-measured steps of the move (one linearized step overshot a 2.3 mm gap by 0.9 mm)


def tip_surface_points(hand) -> torch.Tensor:
    """``(F, P, 3)`` link-frame points on each fingertip link's collision surface (m), spread by
    farthest-point sampling; computed once per hand and kept on it."""
    cached = getattr(hand, "_tip_surface_points", None)
    if cached is not None and cached.device == hand.sphere_radii.device and cached.dtype == hand.sphere_radii.dtype:
        return cached
    out = []
    for f, link in enumerate(hand.fingertip_link_index.tolist()):
        shapes = link_shapes(hand.mj_model, link + 1)  # link i is MuJoCo body i + 1
        if not shapes:
            raise ValueError(f"hand {hand.name!r}: fingertip {hand.fingertip_names[f]!r} link has no collision geometry")
        pts, _ = sample_link_surface(shapes, 20000, np.random.default_rng(0))
        out.append(pts[farthest_point_seeds(torch.as_tensor(pts), TIP_SURFACE_POINTS)])
    hand._tip_surface_points = torch.as_tensor(np.stack(out), dtype=hand.sphere_radii.dtype,
                                               device=hand.sphere_radii.device)
    return hand._tip_surface_points


def real_tip_gaps(hand, targets, object_index: torch.Tensor, root_pose: torch.Tensor, joints: torch.Tensor,
                  tip_index: torch.Tensor) -> torch.Tensor:
    """``(B, F')`` each task fingertip's real gap to its object (m, negative: penetrating): the
    smallest exact signed distance over its link's surface points. ``tip_index (F',)`` indexes
    ``hand.fingertip_names``; root ``(B, 7)``, joints ``(B, J)`` coupled."""
    from datagen.synth.energies import _query_targets

    q = tip_surface_points(hand)[tip_index]  # (F', P, 3)
    T = hand.link_transforms(root_pose, joints)[:, hand.fingertip_link_index[tip_index]]  # (B, F', 4, 4)
    w = (T[:, :, None, :3, :3] @ q[None, :, :, :, None]).squeeze(-1) + T[:, :, None, :3, 3]  # (B, F', P, 3)
    d, _, _ = _query_targets(targets, object_index, w.reshape(w.shape[0], -1, 3), exact=True)
    return d.reshape(w.shape[:3]).amin(-1)


def touch_grasp(hand, targets, object_index: torch.Tensor, root_pose: torch.Tensor, joints: torch.Tensor,
                tip_index: torch.Tensor, tip_spheres: torch.Tensor, inward_normals: torch.Tensor,
                movable: torch.Tensor, damping_m: float = 0.01,
                steps: int = TOUCH_STEPS) -> tuple[torch.Tensor, torch.Tensor]:
    """``(joints (B, J), gaps (B, F'))``: the grasp with every task fingertip moved in along its
    contact normal ``inward_normals (B, F', 3)`` by its real gap (gaps below 0 are left alone),
    coupled and within the joint limits; and the gaps measured before the move (m).

    One damped least-squares step through the fingertip Jacobians is a linearization: the
    fingertip turns as its joints move, so the pad point nearest the surface changes, and a 2 mm
    gap can end 0.9 mm deep. So the move is ``steps`` steps, each re-measuring the real gaps and
    moving the remainder to the goal (0, or the gap itself where it started below 0), in or out."""
    from datagen.synth.squeeze import _damped_step, tip_jacobian

    gaps = real_tip_gaps(hand, targets, object_index, root_pose, joints, tip_index)
    goal = gaps.clamp_max(0)
    mask = movable.to(joints.dtype)
    now = gaps
    for k in range(steps):
        J = tip_jacobian(hand, root_pose, joints, tip_spheres) * mask
        joints = hand.clamp_joints(hand.apply_couplings(joints + _damped_step(J, (now - goal)[..., None] * inward_normals,
                                                                             damping_m)))
        if k + 1 < steps:
            now = real_tip_gaps(hand, targets, object_index, root_pose, joints, tip_index)
    return joints, gaps
