"""Checks of a hand spec against its MJCF/URDF: what ``datagen hand init`` and ``datagen hand check``
report, each finding naming the link, joint or finger, the reason and the remedy.

- kinematics: pytorch-kinematics' FK against MuJoCo's ``mj_kinematics`` on random configurations;
- spheres: every link with collision geometry has spheres, they cover its surface and do not
  reach far beyond it (`spheres.sphere_coverage`, `geometry.union_depth`);
- fingertip pads: each contact point lies on its link's collision surface, its normal is the
  surface's outward normal, and it faces the side the finger closes towards;
- couplings: those the MJCF implies (tight tendons, joint equalities, URDF mimic joints:
  `mjcf.detect_couplings`) are in the spec; every joint is driven by an actuator or a coupling;
- palm and self-collision: the fingers, half-closed, lie in front of the palm; no listed
  self-collision pair overlaps in the open pose (it would always count as penetrating).

Errors make a spec unusable for synthesis (``hand check`` exits 2); warnings are worth a look.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from .closing import closing_signs, link_centre
from .geometry import link_shapes, points_outward, sample_link_surface, union_depth
from .mjcf import detect_couplings
from .spheres import sphere_coverage

__all__ = ["Finding", "Limits", "validate_hand"]


@dataclass(frozen=True)
class Limits:
    """Tolerances of the checks (metres, radians)."""

    fk_m: float = 1e-5              # FK position disagreement with MuJoCo
    coverage: float = 0.9           # surface fraction a link's spheres must cover (warning below)
    overshoot_m: float = 0.006      # a sphere reaching further beyond the collision geometry: error
    pad_offset_m: float = 0.002     # fingertip point this far off its link's collision surface: error
    pad_probe_m: float = 0.001      # the normal is outward if p - this n is inside the link and p + this n is not
    coupling_ratio: float = 1e-3    # a spec coupling's ratio against the one the MJCF implies


@dataclass(frozen=True)
class Finding:
    level: str   # "error" or "warning"
    where: str   # "link 'x'", "joint 'y'", "fingertip 'ff' (link 'z')", "palm", ...
    reason: str
    remedy: str = ""

    def line(self) -> str:
        return f"{self.level}: {self.where}: {self.reason}" + (f" ({self.remedy})" if self.remedy else "")


def _fk(hand, rng, n: int, lim: Limits) -> list[Finding]:
    m = hand.mj_model
    data = mujoco.MjData(m)
    lo, hi = hand.joint_lower.cpu().double().numpy(), hand.joint_upper.cpu().double().numpy()
    worst, where = 0.0, ""
    root = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=hand.dtype, device=hand.device)
    for _ in range(n):
        q = lo + rng.random(len(lo)) * (hi - lo)
        data.qpos[:] = hand.joints_to_qpos(q)
        mujoco.mj_kinematics(m, data)
        T = hand.link_transforms(root, torch.as_tensor(q, dtype=hand.dtype, device=hand.device))
        err = np.abs(T[:, :3, 3].detach().cpu().double().numpy() - data.xpos[1:]).max(axis=1)
        if err.max() > worst:
            worst, where = float(err.max()), hand.link_names[int(err.argmax())]
    tol = lim.fk_m if hand.dtype == torch.float64 else max(lim.fk_m, 1e-4)
    if worst > tol:
        return [Finding("error", f"link {where!r}", f"pytorch-kinematics FK is {worst * 1000:.3f} mm off MuJoCo's",
                        "unsupported MJCF kinematics on its chain (e.g. a joint with a non-zero pos)")]
    return []


def _spheres(hand, rng, lim: Limits) -> list[Finding]:
    m, spec, out = hand.mj_model, hand.spec, []
    for b in range(1, m.nbody):
        name = m.body(b).name
        shapes = link_shapes(m, b)
        spheres = np.asarray(spec.spheres.get(name, ()), dtype=np.float64).reshape(-1, 4)
        if not shapes:
            if len(spheres):
                out.append(Finding("warning", f"link {name!r}", f"{len(spheres)} spheres on a link without "
                                   "collision geometry", "MuJoCo never touches it there: remove them"))
            continue
        if not len(spheres):
            out.append(Finding("error", f"link {name!r}", "has collision geometry but no spheres: synthesis cannot "
                               "see it and poses will penetrate with it", "regenerate the spheres (datagen hand init)"))
            continue
        pts, _ = sample_link_surface(shapes, 2000, rng)
        cov = float(sphere_coverage(spheres, pts).mean())
        if cov < lim.coverage:
            out.append(Finding("warning", f"link {name!r}", f"its spheres cover {cov:.0%} of its collision surface",
                               "raise sphere_fit.coverage or max_spheres_per_link and regenerate"))
        reach = spheres[:, 3] - union_depth(shapes, spheres[:, :3])  # an upper bound of each sphere's overshoot
        k = int(np.argmax(reach))
        if reach[k] > lim.overshoot_m:
            out.append(Finding("error", f"link {name!r}", f"sphere {k} reaches {reach[k] * 1000:.1f} mm beyond the "
                               "collision geometry (poses would stop short of the object)",
                               f"shrink or remove it; the fit allows {spec.sphere_fit.overshoot * 1000:.1f} mm"))
    return out


def _closing_signs(hand, data) -> dict[str, float]:
    """Joint name -> the way it closes (`closing.closing_signs`, as `hand init` derives it)."""
    m = hand.mj_model
    tips = [m.body(t.link).id for t in hand.spec.fingertips.values()]
    signs = closing_signs(m, data, tips, [link_centre(data, b, link_shapes(m, b)) for b in tips])
    return {m.joint(j).name: float(signs[j]) for j in range(m.njnt)}


def _closing_direction(m, data, body: int, point: np.ndarray, signs: dict[str, float]) -> np.ndarray | None:
    """World direction the point of ``body`` moves when its nearest joint closes, or None without
    a joint above it."""
    b = body
    while b != 0 and m.body_jntnum[b] == 0:
        b = int(m.body_parentid[b])
    if b == 0:
        return None
    j = int(m.body_jntadr[b] + m.body_jntnum[b] - 1)
    R, t = data.xmat[body].reshape(3, 3), data.xpos[body]
    return signs[m.joint(j).name] * np.cross(data.xaxis[j], R @ point + t - data.xanchor[j])


def _fingertips(hand, rng, lim: Limits) -> list[Finding]:
    m, spec, out = hand.mj_model, hand.spec, []
    data = mujoco.MjData(m)
    data.qpos[:] = hand.joints_to_qpos(hand.open_pose)
    mujoco.mj_kinematics(m, data)
    signs = _closing_signs(hand, data)
    for fname, tip in spec.fingertips.items():
        where = f"fingertip {fname!r} (link {tip.link!r})"
        b = m.body(tip.link).id
        shapes = link_shapes(m, b)
        if not shapes:
            out.append(Finding("error", where, "its link has no collision geometry", "pick the finger's last link "
                               "with collision geometry"))
            continue
        if not spec.spheres.get(tip.link):
            out.append(Finding("error", where, "its link has no collision spheres", "regenerate the spheres"))
        p, n = np.asarray(tip.point), np.asarray(tip.normal)
        off = float(abs(union_depth(shapes, p[None])[0]))
        if off > lim.pad_offset_m:
            out.append(Finding("error", where, f"the contact point lies {off * 1000:.1f} mm off the link's collision "
                               "surface", "move it onto the pad (datagen hand init proposes one)"))
            continue
        # outward: a step along the normal leaves the link, a step against it enters (robust at
        # the edges of boxes and hulls, where a surface gradient is undefined)
        if not points_outward(shapes, p, n, lim.pad_probe_m):
            out.append(Finding("error", where, "the normal does not point out of the link's collision surface",
                               "set it to the pad's outward normal"))
        closing = _closing_direction(m, data, b, p, signs)
        R = data.xmat[b].reshape(3, 3)
        if closing is not None and np.linalg.norm(closing) > 1e-9 and float((R @ n) @ closing) < 0:
            out.append(Finding("warning", where, "the pad faces away from where the finger closes (the back of the "
                               "finger?)", "check the picture; put the point on the palm side of the fingertip"))
    return out


def _couplings(hand, lim: Limits) -> list[Finding]:
    m, spec, out = hand.mj_model, hand.spec, []
    mine = {c.joint: c for c in spec.couplings}
    for c in detect_couplings(m):
        have = mine.get(c.joint)
        if have is None:
            out.append(Finding("error", f"joint {c.joint!r}", f"the MJCF couples it to {c.leader!r} (ratio {c.ratio:.4g}, "
                               "a tendon, equality or mimic joint) but the spec does not: synthesized poses "
                               "cannot be held", f"add couplings: [{{joint: {c.joint}, leader: {c.leader}, ratio: "
                               f"{c.ratio:.6g}, offset: {c.offset:.6g}}}]"))
        elif have.leader != c.leader or abs(have.ratio - c.ratio) > lim.coupling_ratio * max(1.0, abs(c.ratio)):
            out.append(Finding("warning", f"joint {c.joint!r}", f"spec coupling (leader {have.leader!r}, ratio "
                               f"{have.ratio:.4g}) differs from the MJCF's ({c.leader!r}, {c.ratio:.4g})",
                               "use the MJCF's unless the model is known to be wrong"))
    driven = np.abs(hand.ctrl_matrix.cpu().double().numpy()).sum(axis=0) > 0
    followers = {c.joint for c in spec.couplings}
    for j, name in enumerate(hand.joint_names):
        if not driven[j] and name not in followers:
            out.append(Finding("error", f"joint {name!r}", "no actuator drives it and no coupling sets it: MuJoCo "
                               "cannot hold a synthesized pose", "add a position actuator to the MJCF, or a coupling"))
    return out


def _palm_and_pairs(hand) -> list[Finding]:
    out = []
    root = torch.tensor([0, 0, 0, 1.0, 0, 0, 0], dtype=hand.dtype, device=hand.device)
    q0 = hand.open_pose
    lo, hi = hand.joint_lower, hand.joint_upper
    data = mujoco.MjData(hand.mj_model)
    data.qpos[:] = hand.joints_to_qpos(q0)
    mujoco.mj_kinematics(hand.mj_model, data)
    signs = _closing_signs(hand, data)
    up = torch.tensor([signs[n] > 0 for n in hand.joint_names], device=lo.device)
    flexed = hand.apply_couplings(torch.where(up, hi, lo) * 0.5 + q0 * 0.5)
    palm = hand.palm_frame(root, q0)
    # where the fingers close: their pads half-closed lie in front of the palm (a flat hand's
    # pads move along the approach as they close; a claw's, pointing along it, move back a little)
    grasp = hand.fingertip_points(root, flexed).mean(0) - palm.origin
    if float(grasp @ palm.approach) <= 0:
        out.append(Finding("error", "palm", "the approach axis points away from where the fingers close",
                           "flip palm.approach (it is the palm normal, out of the palm)"))
    pen = hand.self_penetration(root, q0)
    if pen.numel() and float(pen.max()) > 0:
        k = int(pen.argmax())
        i, j = (int(x) for x in hand.self_collision_pairs[k])
        a, b = hand.link_names[int(hand.sphere_link_index[i])], hand.link_names[int(hand.sphere_link_index[j])]
        out.append(Finding("error", f"self-collision pair ({a!r}, {b!r})", f"overlaps by {float(pen.max()) * 1000:.1f} mm "
                           "in the open pose: every pose would count as self-penetrating",
                           "drop the pair or the overlapping spheres from self_collision_pairs"))
    return out


def validate_hand(hand, *, samples: int = 16, seed: int = 0, limits: Limits | None = None) -> list[Finding]:
    """Every finding of the checks above on a loaded hand (`datagen.hands.load_hand`), errors first."""
    lim = limits or Limits()
    rng = np.random.default_rng(seed)
    found = (_fk(hand, rng, samples, lim) + _spheres(hand, rng, lim) + _fingertips(hand, rng, lim)
             + _couplings(hand, lim) + _palm_and_pairs(hand))
    return sorted(found, key=lambda f: f.level != "error")
