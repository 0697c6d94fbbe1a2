"""Initial hand poses: the palm faces the object from outside its convex hull, fingers open.

``surround`` (force closure, NOTES §2): a random point of the object's convex hull, pushed out
along the hull normal by ``distance_m``; the palm's approach axis points back along the normal
(tilted by up to ``tilt_deg``), rolled by up to ``roll_deg`` about it, origin jittered
laterally by up to ``offset_m``. ``approach``: the palm faces along ``approach`` from the hull's
supporting plane perpendicular to it, aimed at ``target_m``, thumb towards ``thumb`` (rolled by up
to ``roll_deg``); ``above`` is ``approach`` with the palm down (-z) aimed at the origin. With ``aim:
fingertips`` (``approach`` only) it is not the palm but the centre of the task's fingertips (the
midpoint of the two farthest apart, at the initial joints) that lands on ``target_m``, backed off
by ``distance_m`` against the approach: a precision grasp's fingertips start around the part
they pinch, wherever the hand's palm frame lies; there ``thumb`` gives the direction from the other
task fingertips to the thumb tip (the pinch axis), not the palm's thumb axis.
With ``scenery`` (static boxes round a mounted task object, the table under a tabletop
target: `datagen.synth.scenery`), ``surround`` draws only hull points
whose palm origins, at both ends of ``distance_m``, stay `SCENERY_CLEARANCE_M` clear of every box,
and a start with a collision sphere in a box is drawn again: no hand starts behind a door, with
its forearm in a cabinet or below the table (a tabletop object is approached from above and
from the side).
``rim`` (the edge pinch of an object lying flat, `_draw_rim`): down the table's up direction,
the pinch axis across the footprint's narrowest width, the task tips' centre over the
footprint's centre at the object's mid-height (`datagen.synth.GraspTarget.footprint`).
``wrap`` (a power grasp sized to the object, `_draw_wrap`): the palm faces the object across
its longest principal axis (of its convex hull, `shape_axes`) from that side's hull plane, the
pinch axis across its cross-section, near the thinnest way through it for a flat section and
anywhere round a round one: a bottle or a box is wrapped round its thin side, not across its
length. In scenery (a table, a mount) ``wrap`` starts are ``surround`` starts with the default
roll (from the side of a low object the hand goes through the table: 14% of such starts on a
2 cm high box were clear of it).
Joints start at the hand's open pose, or with ``curl`` > 0 each finger's flexion joints part of the
way to their limit (:func:`curled_joints`: a hook, for grasps that wrap round a handle). Everything
is drawn from the passed generator.
"""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from datagen.synth.rotation import matrix_to_quat

__all__ = ["SCENERY_CLEARANCE_M", "SCENERY_REDRAWS", "WRAP_SLIDE", "curled_joints", "fingertip_centre", "initial_poses",
           "root_from_palm", "shape_axes"]

SCENERY_CLEARANCE_M = 0.01  #: m, how far outside the scenery a ``surround`` palm origin starts
SCENERY_REDRAWS = 64  #: times a start with the hand in the scenery is drawn again (82% of generic lever starts are)
WRAP_SLIDE = 0.25  #: ``wrap``: the palm starts up to this fraction of the object's half-length off its middle


def _unit(x: torch.Tensor) -> torch.Tensor:
    return x / x.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _any_perpendicular(a: torch.Tensor) -> torch.Tensor:
    ref = torch.where((a[..., :1].abs() < 0.9), torch.tensor([1.0, 0, 0], dtype=a.dtype, device=a.device),
                      torch.tensor([0, 1.0, 0], dtype=a.dtype, device=a.device))
    return _unit(torch.linalg.cross(a, ref))


def _rotate_about(v: torch.Tensor, axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rodrigues rotation of ``v (..., 3)`` about unit ``axis (..., 3)`` by ``angle (...)``."""
    c, s = torch.cos(angle)[..., None], torch.sin(angle)[..., None]
    return v * c + torch.linalg.cross(axis, v) * s + axis * (axis * v).sum(-1, keepdim=True) * (1 - c)


def _frame(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation with columns u, v made orthogonal to u, u x v (unit)."""
    u = _unit(u)
    v = _unit(v - (v * u).sum(-1, keepdim=True) * u)
    return torch.stack([u, v, torch.linalg.cross(u, v)], dim=-1)


def root_from_palm(hand, origin: torch.Tensor, approach: torch.Tensor, thumb: torch.Tensor,
                   pinch: torch.Tensor | None = None) -> torch.Tensor:
    """Root poses ``(B, 7)`` placing the open hand's palm frame at world ``origin``/axes ``(B, 3)``.

    With ``pinch`` (3,), a vector in the hand's root frame (the thumb tip minus the other task
    tips), that vector is turned exactly onto ``thumb`` and the palm's approach axis as close
    to ``approach`` as that leaves it."""
    B = origin.shape[0]
    ident = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=hand.dtype, device=hand.device)
    palm = hand.palm_frame(ident, hand.open_pose)
    if pinch is None:
        R = _frame(approach, thumb) @ _frame(palm.approach, palm.thumb).T
    else:
        R = _frame(thumb, approach) @ _frame(pinch, palm.approach).T
    pos = origin - (R @ palm.origin[:, None]).squeeze(-1)
    return torch.cat([pos, matrix_to_quat(R)], dim=-1).reshape(B, 7)


def curled_joints(hand, fraction: float, step_rad: float = 1e-3) -> torch.Tensor:
    """(J,) the open pose with each finger's flexion joints ``fraction`` (0..1) of the way to
    the limit that moves the fingertip out of the palm's face (along its approach axis).

    A joint counts as flexion when it moves exactly one fingertip (not the wrist) and mostly
    along the palm normal (abduction moves it sideways): found by finite differences through
    the forward kinematics at the open pose, so it holds for any hand."""
    ident = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=hand.dtype, device=hand.device)
    q0 = hand.open_pose
    approach = _unit(hand.palm_frame(ident, q0).approach)
    tips0 = hand.fingertip_points(ident, q0)  # (F, 3)
    dq = step_rad * torch.eye(hand.num_joints, dtype=hand.dtype, device=hand.device)
    motion = (hand.fingertip_points(ident, q0 + dq) - tips0) / step_rad  # (J, F, 3) m/rad
    speed = motion.norm(dim=-1)  # (J, F)
    along = (motion * approach).sum(-1)  # (J, F)
    out = q0.clone()
    for j in range(hand.num_joints):
        moved = speed[j] > 1e-3  # > 1 mm/rad
        if int(moved.sum()) != 1:
            continue  # wrist (moves every tip) or a joint with no effect here
        f = int(moved.nonzero())
        if along[j, f].abs() < 0.5 * speed[j, f]:
            continue  # abduction: mostly sideways
        limit = hand.joint_upper[j] if along[j, f] > 0 else hand.joint_lower[j]
        out[j] = q0[j] + fraction * (limit - q0[j])
    return hand.apply_couplings(out)


def fingertip_centre(hand, root: torch.Tensor, joints: torch.Tensor, tip_index) -> torch.Tensor:
    """(B, 3) midpoint of the two farthest apart fingertips ``tip_index`` (all when None), m."""
    tips = hand.fingertip_points(root, joints)  # (B, F, 3)
    if tip_index is not None:
        tips = tips[:, list(tip_index)]
    if tips.shape[1] == 1:
        return tips[:, 0]
    gap = (tips[:, :, None] - tips[:, None]).norm(dim=-1).flatten(1)  # (B, F*F)
    i, j = gap.argmax(-1).div(tips.shape[1], rounding_mode="floor"), gap.argmax(-1) % tips.shape[1]
    rows = torch.arange(tips.shape[0], device=tips.device)
    return 0.5 * (tips[rows, i] + tips[rows, j])


def _pinch_vector(hand, joints: torch.Tensor, tip_index) -> torch.Tensor | None:
    """(3,) thumb tip minus the mean of the other task tips, root frame, at ``joints`` (J,);
    None without a thumb (the spec's ``thumb_finger``) and another finger among the task's tips."""
    names, thumb = hand.fingertip_names, hand.spec.thumb_finger
    tips = list(range(len(names))) if tip_index is None else list(tip_index)
    if thumb is None or names.index(thumb) not in tips or len(tips) < 2:
        return None
    ident = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=hand.dtype, device=hand.device)
    pts = hand.fingertip_points(ident, joints)
    th = names.index(thumb)
    return pts[th] - pts[[i for i in tips if i != th]].mean(0)


def initial_poses(hand, targets, object_index: torch.Tensor, init_cfg, generator: torch.Generator,
                  tip_index=None, scenery=None):
    """``(root_pose (B, 7), joints (B, J))`` for grasps on ``targets[object_index]``;
    ``tip_index``: the task's fingertips (for ``aim: fingertips``; None: all); ``scenery``: a
    `datagen.synth.scenery.Scenery` the hand starts clear of (None: none): ``surround`` palms
    come from hull points with room for them, and a pose with any collision sphere inside the
    scenery (a forearm through the door) is drawn again, up to `SCENERY_REDRAWS` times (the
    least deep of its draws is kept)."""
    root, joints = _draw(hand, targets, object_index, init_cfg, generator, tip_index, scenery)
    if scenery is None:
        return root, joints

    def depth(r, j):
        centres, radii = hand.spheres(r, j)
        return scenery.penetration(object_index, centres, radii).amax(-1)

    d = depth(root, joints)
    for _ in range(SCENERY_REDRAWS):
        if not bool((d > 0).any()):
            break
        r2, j2 = _draw(hand, targets, object_index, init_cfg, generator, tip_index, scenery)
        d2 = depth(r2, j2)
        better = d2 < d
        root, joints = torch.where(better[:, None], r2, root), torch.where(better[:, None], j2, joints)
        d = torch.minimum(d, d2)
    return root, joints


def _draw(hand, targets, object_index, init_cfg, generator, tip_index, scenery):
    """One draw of `initial_poses` for every sample (no redraws)."""
    B = object_index.shape[0]
    dt, dev = hand.dtype, hand.device

    def rand(*shape):
        return torch.rand(*shape, generator=generator, dtype=torch.float64).to(dev, dt)

    if init_cfg.kind == "rim":
        return _draw_rim(hand, targets, object_index, init_cfg, rand, tip_index)
    if init_cfg.kind == "wrap":
        if scenery is None or not any(scenery.applies_to(k) for k in range(len(targets))):
            return _draw_wrap(hand, targets, object_index, init_cfg, rand, tip_index)
        # a wrap from the side of an object on a table puts the hand through it: the task's start
        init_cfg = replace(init_cfg, kind="surround", roll_deg=type(init_cfg).__dataclass_fields__["roll_deg"].default)
    fingertips = init_cfg.kind == "approach" and init_cfg.aim == "fingertips"
    origin = torch.empty(B, 3, dtype=dt, device=dev)
    normal = torch.empty(B, 3, dtype=dt, device=dev)
    for k, target in enumerate(targets):
        sel = (object_index == k).nonzero().squeeze(-1)
        if sel.numel() == 0:
            continue
        if init_cfg.kind == "surround":
            pts, nrm = target.hull_points.to(dev, dt), target.hull_normals.to(dev, dt)
            if scenery is not None and scenery.applies_to(k):
                lo, hi = init_cfg.distance_m
                ok = (scenery.clear_of(pts + lo * nrm, SCENERY_CLEARANCE_M, k)
                      & scenery.clear_of(pts + hi * nrm, SCENERY_CLEARANCE_M, k))
                if not bool(ok.any()):
                    raise ValueError(f"{target.object_id}: no convex-hull point has room for a palm outside the "
                                     f"task's scenery (distance_m {init_cfg.distance_m})")
                pts, nrm = pts[ok], nrm[ok]
            idx = (rand(sel.numel()) * pts.shape[0]).long().clamp_max(pts.shape[0] - 1)
            origin[sel] = pts[idx]
            normal[sel] = nrm[idx]
        else:  # above / approach: palm on the hull's supporting plane facing -approach, aimed at target
            a = -1.0 * torch.tensor(init_cfg.approach if init_cfg.kind == "approach" else (0, 0, -1.0), dtype=dt, device=dev)
            n = _unit(a)
            target_pt = torch.tensor(init_cfg.target_m if init_cfg.kind == "approach" else (0, 0, 0.0), dtype=dt, device=dev)
            if fingertips:
                reach = 0.0  # the fingertips go to the target itself, not to the hull's plane
            else:
                reach = ((target.hull_points.to(dev, dt) - target_pt) @ n).max()
            origin[sel] = (target_pt + n * reach).expand(sel.numel(), 3)
            normal[sel] = n.expand(sel.numel(), 3)
    lo, hi = init_cfg.distance_m
    dist = lo + (hi - lo) * rand(B)
    lateral = _any_perpendicular(normal)
    lateral = _rotate_about(lateral, normal, 2 * math.pi * rand(B))
    origin = origin + normal * dist[:, None] + lateral * (init_cfg.offset_m * (2 * rand(B) - 1))[:, None]
    approach = -normal
    tilt_axis = _rotate_about(_any_perpendicular(approach), approach, 2 * math.pi * rand(B))
    approach = _rotate_about(approach, tilt_axis, math.radians(init_cfg.tilt_deg) * (2 * rand(B) - 1))
    open_joints = curled_joints(hand, init_cfg.curl) if init_cfg.curl > 0 else hand.open_pose
    if init_cfg.kind == "approach" and init_cfg.thumb is not None:
        hint = torch.tensor(init_cfg.thumb, dtype=dt, device=dev).expand(B, 3)
        base = _unit(hint - (hint * approach).sum(-1, keepdim=True) * approach)
        pinch = _pinch_vector(hand, open_joints, tip_index) if fingertips else None
    else:
        base, pinch = _any_perpendicular(approach), None
    thumb = _rotate_about(base, approach, math.radians(init_cfg.roll_deg) * (2 * rand(B) - 1))
    root = root_from_palm(hand, origin, approach, thumb, pinch)
    joints = open_joints.expand(B, -1).clone()
    if fingertips:
        shift = origin - fingertip_centre(hand, root, joints, tip_index)
        root = torch.cat([root[:, :3] + shift, root[:, 3:]], -1)
    return root, joints


def _draw_rim(hand, targets, object_index, init_cfg, rand, tip_index):
    """One draw of ``rim`` starts: the palm comes down the table's up direction (tilted by up to
    ``tilt_deg``) with the pinch axis (thumb tip minus the other task tips, at the initial
    joints) across the footprint's narrowest width (either way, rolled by up to ``roll_deg``),
    the task tips' centre ``distance_m`` above the object's mid-height over the footprint's
    centre (jittered by up to ``offset_m`` on the table): thumb and fingers open on opposite
    rims of an object lying flat (`datagen.synth.GraspTarget.footprint`)."""
    B = object_index.shape[0]
    dt, dev = hand.dtype, hand.device
    up, axis, centre = (torch.empty(B, 3, dtype=dt, device=dev) for _ in range(3))
    for k, target in enumerate(targets):
        sel = (object_index == k).nonzero().squeeze(-1)
        if sel.numel():
            fp = target.footprint
            up[sel] = torch.as_tensor(fp.up, dtype=dt, device=dev)
            axis[sel] = torch.as_tensor(fp.axis, dtype=dt, device=dev)
            centre[sel] = torch.as_tensor(fp.centre + 0.5 * fp.height * fp.up, dtype=dt, device=dev)
    lo, hi = init_cfg.distance_m
    lateral = _rotate_about(axis, up, 2 * math.pi * rand(B))
    origin = centre + up * (lo + (hi - lo) * rand(B))[:, None] + lateral * (init_cfg.offset_m * (2 * rand(B) - 1))[:, None]
    tilt_axis = _rotate_about(axis, up, 2 * math.pi * rand(B))
    approach = _rotate_about(-up, tilt_axis, math.radians(init_cfg.tilt_deg) * (2 * rand(B) - 1))
    sign = torch.where(rand(B) < 0.5, -1.0, 1.0).to(dt)[:, None]
    thumb = _rotate_about(axis * sign, up, math.radians(init_cfg.roll_deg) * (2 * rand(B) - 1))
    joints = (curled_joints(hand, init_cfg.curl) if init_cfg.curl > 0 else hand.open_pose).expand(B, -1).clone()
    pinch = _pinch_vector(hand, joints[0], tip_index)
    root = root_from_palm(hand, origin, approach, thumb, pinch)
    shift = origin - fingertip_centre(hand, root, joints, tip_index)
    return torch.cat([root[:, :3] + shift, root[:, 3:]], -1), joints


def shape_axes(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(centre (3,), axes (3, 3), extents (3,))`` of ``points (H, 3)`` (m): the principal axes
    of their covariance as the columns of ``axes``, ordered by the points' extent along them
    (longest first), and the centre of that box (computed in float64, returned in the points'
    dtype)."""
    x = points.double()
    _, vecs = torch.linalg.eigh(torch.cov(x.T))
    proj = (x - x.mean(0)) @ vecs
    lo, hi = proj.amin(0), proj.amax(0)
    order = (hi - lo).argsort(descending=True)
    centre = x.mean(0) + vecs @ (0.5 * (lo + hi))
    return tuple(t.to(points.dtype) for t in (centre, vecs[:, order], (hi - lo)[order]))


def _draw_wrap(hand, targets, object_index, init_cfg, rand, tip_index):
    """One draw of ``wrap`` starts. Per object, its hull's principal axes e1 (longest), e2, e3
    with widths w1 >= w2 >= w3 (`shape_axes`). The pinch axis (thumb tip minus the other tips,
    `_pinch_vector`; the palm's thumb axis along e1 for a hand without a thumb) goes onto u =
    cos(psi) e3 + sin(psi) e2 with tan(psi) = (w3 / w2)^2 tan(phi), phi uniform: round
    sections get every direction, flat ones close to their thinnest. The palm faces the object
    along n = e1 x u, from ``distance_m`` off the hull's extent along n among the hull points
    within 2 cm of its line (slid up to `WRAP_SLIDE` of the half-length along e1, jittered by
    ``offset_m``), tilted by up to ``tilt_deg``, rolled by up to ``roll_deg``."""
    B = object_index.shape[0]
    dt, dev = hand.dtype, hand.device
    origin, normal, thumb = (torch.empty(B, 3, dtype=dt, device=dev) for _ in range(3))
    for k, target in enumerate(targets):
        sel = (object_index == k).nonzero().squeeze(-1)
        if sel.numel() == 0:
            continue
        pts = target.hull_points.to(dev, dt)
        centre, axes, widths = shape_axes(pts)
        e1, e2, e3 = axes.T
        m = sel.numel()
        phi = 2 * math.pi * rand(m)
        ratio = (widths[2] / widths[1].clamp_min(1e-9)) ** 2
        u = _unit(torch.cos(phi)[:, None] * e3 + (ratio * torch.sin(phi))[:, None] * e2)
        n = _unit(torch.linalg.cross(e1.expand(m, 3), u))
        line = centre + (WRAP_SLIDE * 0.5 * widths[0] * (2 * rand(m) - 1))[:, None] * e1
        rel = pts[None] - line[:, None]  # (m, H, 3)
        near = (rel - (rel * e1).sum(-1, keepdim=True) * e1 - (rel * n[:, None]).sum(-1, keepdim=True) * n[:, None])
        reach = (rel * n[:, None]).sum(-1)  # (m, H)
        close = near.norm(dim=-1) < 0.02
        reach = torch.where(close.any(-1), reach.masked_fill(~close, -math.inf).amax(-1), reach.amax(-1))
        origin[sel] = line + n * reach[:, None]
        normal[sel] = n
        thumb[sel] = u
    lo, hi = init_cfg.distance_m
    lateral = _rotate_about(_any_perpendicular(normal), normal, 2 * math.pi * rand(B))
    origin = origin + normal * (lo + (hi - lo) * rand(B))[:, None] + lateral * (init_cfg.offset_m * (2 * rand(B) - 1))[:, None]
    tilt_axis = _rotate_about(_any_perpendicular(normal), normal, 2 * math.pi * rand(B))
    approach = _rotate_about(-normal, tilt_axis, math.radians(init_cfg.tilt_deg) * (2 * rand(B) - 1))
    sign = torch.where(rand(B) < 0.5, -1.0, 1.0).to(dt)[:, None]
    thumb = thumb - (thumb * approach).sum(-1, keepdim=True) * approach
    thumb = _rotate_about(_unit(thumb) * sign, approach, math.radians(init_cfg.roll_deg) * (2 * rand(B) - 1))
    joints = (curled_joints(hand, init_cfg.curl) if init_cfg.curl > 0 else hand.open_pose).expand(B, -1).clone()
    pinch = _pinch_vector(hand, joints[0], tip_index)
    if pinch is None:  # no thumb: the palm's thumb axis along the long axis, the fingers across the section
        thumb = _unit(torch.linalg.cross(approach, thumb))
    return root_from_palm(hand, origin, approach, thumb, pinch), joints
