"""Static scenery in synthesis: boxes round a mounted task object that the hand must stay out of.

A task whose object is mounted (a lever on a closed door, a knob on a panel, a button in its
housing, a drawer front in its cabinet; `datagen.tasks.task_scenery`) comes with axis-aligned
boxes in the object frame (metres). They add to the collision-sphere penetration term, exactly
as the object does: ``max(0, reach_s - sd(c_s))`` per sphere, ``sd`` the signed distance to the
nearest box, so a hand cannot wrap round the back of a door or pinch a button cap through its
bezel. They apply to the samples on the task's own object only, and they take generic initial
palms (``surround``) off the hull points that face into them (`Scenery.clear_of`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["Scenery", "box_distance"]


def box_distance(points: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Signed distance ``(..., K)`` (m; negative inside) of points ``(..., 3)`` to K axis-aligned
    boxes ``lo``, ``hi`` ``(K, 3)``. Differentiable everywhere a point is not on a box's medial
    set (its gradient is the outward normal of the nearest face, edge or corner)."""
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    q = (points[..., None, :] - centre).abs() - half  # (..., K, 3)
    out = q.clamp_min(0).square().sum(-1)
    # sqrt's gradient is unbounded at 0, where clamp_min's is 0: keep the product finite
    outside = torch.where(out > 0, out, torch.ones_like(out)).sqrt() * (out > 0)
    return outside + q.amax(-1).clamp_max(0)


@dataclass(frozen=True)
class Scenery:
    """K boxes ``lo``, ``hi`` ``(K, 3)`` metres (object frame) and ``on_target`` ``(T,)`` bool:
    the targets (of the synthesis batch) they belong to."""

    lo: torch.Tensor
    hi: torch.Tensor
    on_target: torch.Tensor

    @classmethod
    def for_task(cls, task, targets, device, dtype) -> "Scenery | None":
        """The task's scenery on the targets that are its object (None: no boxes or no such target)."""
        from datagen.tasks import task_object_id, task_scenery

        boxes = task_scenery(task)
        oid = task_object_id(task)
        mask = torch.tensor([t.object_id == oid for t in targets], dtype=torch.bool, device=device)
        if not boxes or not bool(mask.any()):
            return None
        lo = torch.tensor([b[0] for b in boxes], dtype=dtype, device=device)
        hi = torch.tensor([b[1] for b in boxes], dtype=dtype, device=device)
        return cls(lo, hi, mask)

    def distance(self, object_index: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        """``(B, N)`` m: signed distance of points ``(B, N, 3)`` to the nearest box; +inf for the
        samples (``object_index`` ``(B,)``) on other targets."""
        d = box_distance(points, self.lo.to(points.dtype), self.hi.to(points.dtype)).amin(-1)
        return torch.where(self.on_target[object_index][:, None], d, torch.full_like(d, torch.inf))

    def penetration(self, object_index: torch.Tensor, centres: torch.Tensor, reach: torch.Tensor) -> torch.Tensor:
        """``(B, S)`` m: ``max(0, reach - sd)`` of sphere centres ``(B, S, 3)``, reach ``(S,)`` m."""
        return torch.relu(reach - self.distance(object_index, centres))

    def clear_of(self, points: torch.Tensor, clearance_m: float) -> torch.Tensor:
        """``(N,)`` bool: points ``(N, 3)`` m at least ``clearance_m`` outside every box."""
        return box_distance(points, self.lo.to(points.dtype), self.hi.to(points.dtype)).amin(-1) >= clearance_m
