"""How low a hand's fingertip pads reach above a table, from its kinematics alone (issue 45).

For an object lying on a table the fingertips must touch its sides below its top, and a pinch
that lifts a round one must touch it near its equator. This estimates, per hand, the lowest
height of the fingertip contact points (the spec's pad points) above the table when the hand's
lowest collision sphere touches it, over poses drawn at random (uniform root orientations, joints
uniform in their limits, couplings applied; a sampled estimate: the true minimum is at most this):

- ``pinch``: thumb and index pads within 30 deg of horizontal, facing each other (normals
  within 60 deg of opposite), at least 2 cm apart: max(thumb, index) height, by the palm
  approach's tilt from straight down (0-30 deg: from above; 60-90: from the side);
- ``claw``: the palm within 20 deg of straight down, every finger's flexion joints at
  ``curl`` (the edge pinch's start, `datagen.synth.init.curled_joints`): each pad's lowest
  height, the pads' median vertical normal component (0: facing sideways) and the median
  thumb-to-fingers span.

    python -m benchmarks.diagnose_table_reach --hands shadow shadow_e3m5 allegro leap
"""

from __future__ import annotations

import argparse
import math

import torch

from datagen.hands import load_hand
from datagen.synth.init import curled_joints

TILTS = (0, 30, 60, 90)  #: deg, the lower ends of the approach-tilt bins (30 deg wide)
CURLS = (0.0, 0.15, 0.3, 0.5)


def _root(q: torch.Tensor) -> torch.Tensor:
    return torch.cat([torch.zeros(q.shape[0], 3, dtype=q.dtype), q], -1)


def _heights(hand, root, joints):
    """(pad heights (N, F) m above the lowest sphere's bottom, pad normals (N, F, 3), palm approach (N, 3))."""
    centres, radii = hand.spheres(root, joints)
    low = (centres[..., 2] - radii).amin(-1)
    return (hand.fingertip_points(root, joints)[..., 2] - low[:, None], hand.fingertip_normals(root, joints),
            hand.palm_frame(root, joints).approach)


def lowest_pinch(hand, gen: torch.Generator, n: int, reps: int) -> dict[int, float]:
    """Tilt bin (deg) -> the lowest thumb-index pinch height found (m)."""
    th, ff = hand.fingertip_names.index(hand.spec.thumb_finger), 1
    best: dict[int, float] = {}
    for _ in range(reps):
        q = torch.nn.functional.normalize(torch.randn(n, 4, generator=gen, dtype=hand.dtype), dim=-1)
        u = torch.rand(n, hand.num_joints, generator=gen, dtype=hand.dtype)
        joints = hand.apply_couplings(hand.joint_lower + (hand.joint_upper - hand.joint_lower) * u)
        z, nrm, approach = _heights(hand, _root(q), joints)
        tilt = torch.rad2deg(torch.acos((-approach[:, 2]).clamp(-1, 1)))
        ok = (nrm[:, th, 2].abs() < 0.5) & (nrm[:, ff, 2].abs() < 0.5) & ((nrm[:, th] * nrm[:, ff]).sum(-1) < -0.5)
        ok &= (hand.fingertip_points(_root(q), joints)[:, [th, ff]].diff(dim=1).norm(dim=-1)[:, 0] > 0.02)
        height = torch.maximum(z[:, th], z[:, ff])
        for lo in TILTS:
            sel = ok & (tilt >= lo) & (tilt < lo + 30)
            if bool(sel.any()):
                best[lo] = min(best.get(lo, math.inf), float(height[sel].min()))
    return best


def claw(hand, gen: torch.Generator, curl: float, n: int):
    """(lowest pad heights (F,) m, median pad normal z (F,), median span m) of claws from above."""
    joints = (curled_joints(hand, curl) if curl > 0 else hand.open_pose).expand(n, -1)
    q = torch.nn.functional.normalize(torch.randn(n, 4, generator=gen, dtype=hand.dtype), dim=-1)
    approach = hand.palm_frame(_root(q), joints).approach
    keep = approach[:, 2] < -math.cos(math.radians(20))
    root, joints = _root(q[keep]), joints[keep]
    z, nrm, _ = _heights(hand, root, joints)
    tips = hand.fingertip_points(root, joints)
    th = hand.fingertip_names.index(hand.spec.thumb_finger)
    others = [i for i in range(tips.shape[1]) if i != th]
    span = (tips[:, th] - tips[:, others].mean(1)).norm(dim=-1).median()
    return z.amin(0), nrm[..., 2].median(0).values, float(span)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hands", nargs="+", default=["shadow", "shadow_e3m5", "allegro", "leap"])
    p.add_argument("--samples", type=int, default=20000, help="poses per draw (about 2 GB of memory at 20000 for Shadow; it grows with it)")
    p.add_argument("--reps", type=int, default=15, help="draws of --samples poses for the pinch")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    torch.set_num_threads(1)
    print("| hand | lowest thumb-index pinch, mm, by approach tilt " + " / ".join(f"{t}-{t + 30}" for t in TILTS)
          + " deg | claw from above: lowest pads mm (thumb first), pads' median n_z, span mm, by curl |")
    print("|---|---|---|")
    for name in a.hands:
        hand = load_hand(name)
        gen = torch.Generator().manual_seed(a.seed)
        pinch = lowest_pinch(hand, gen, a.samples, a.reps)
        cells = []
        for curl in CURLS:
            low, nz, span = claw(hand, gen, curl, a.samples)
            cells.append(f"{curl}: {[round(1000 * v) for v in low.tolist()]}, {[round(v, 1) for v in nz.tolist()]}, "
                         f"{1000 * span:.0f}")
        print(f"| {name} | " + " / ".join(f"{1000 * pinch[t]:.1f}" if t in pinch else "-" for t in TILTS)
              + " | " + "; ".join(cells) + " |")


if __name__ == "__main__":
    main()
