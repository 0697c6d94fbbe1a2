"""Static scenery in synthesis: boxes round a mounted task object, and the table under an object
resting on it, that the hand must stay out of.

A task whose object is mounted (a lever on a closed door, a knob on a panel, a button in its
housing, a drawer front in its cabinet; `datagen.tasks.task_scenery`) comes with axis-aligned
boxes in the object frame (metres). They add to the collision-sphere penetration term, exactly
as the object does: ``max(0, reach_s - sd(c_s))`` per sphere, ``sd`` the signed distance to the
nearest box, so a hand cannot wrap round the back of a door or pinch a button cap through its
bezel. They apply to the samples on the task's own object only, and they take generic initial
palms (``surround``) off the hull points that face into them (`Scenery.clear_of`).

A tabletop target (`datagen.synth.GraspTarget.support_plane`: the table as the plane
``n . x + d = 0`` in the object frame) adds the half-space below its plane the same way: a
sphere's signed distance to it is ``n . c + d - lift``, its penetration
``max(0, reach - (n . c + d - lift))``, and initial palms come only from above the table. The
table is raised by ``lift`` = the sphere margin + `TABLE_CLEARANCE_M`: the hand touches the
object through spheres sunk by the margin, but must not touch the table at all, and its spheres
do not cover every corner of its collision geoms (a sphere exactly on the table left MuJoCo's
Shadow geoms 1.3-1.6 mm deep in it).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["TABLE_CLEARANCE_M", "Scenery", "box_distance", "plane_distance"]

TABLE_CLEARANCE_M = 0.002  #: m the hand's spheres keep above the table beyond their margin


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


def plane_distance(points: torch.Tensor, planes: torch.Tensor) -> torch.Tensor:
    """Signed distance ``(...)`` (m; negative below) of points ``(..., 3)`` above planes ``(..., 4)``
    ``[n, d]`` (unit normal ``n``): ``n . x + d``."""
    return (points * planes[..., :3]).sum(-1) + planes[..., 3]


@dataclass(frozen=True)
class Scenery:
    """K boxes ``lo``, ``hi`` ``(K, 3)`` metres (object frame) and ``on_target`` ``(T,)`` bool:
    the targets (of the synthesis batch) they belong to; ``planes`` ``(T, 4)``: each target's
    support plane ``[n, d]`` (`plane_distance`), raised by ``lift`` m, and ``on_table``
    ``(T,)`` bool the targets that rest on one (None: no table)."""

    lo: torch.Tensor
    hi: torch.Tensor
    on_target: torch.Tensor
    planes: torch.Tensor | None = None
    on_table: torch.Tensor | None = None

    @classmethod
    def for_task(cls, task, targets, device, dtype, sphere_margin_m: float = 0.0) -> "Scenery | None":
        """The task's scenery on the targets that are its object, and the table under the targets
        that rest on one, raised by ``sphere_margin_m`` + `TABLE_CLEARANCE_M` (None: no boxes on
        these targets and no table)."""
        from datagen.tasks import task_object_id, task_scenery

        boxes = task_scenery(task)
        oid = task_object_id(task)
        mask = torch.tensor([t.object_id == oid for t in targets], dtype=torch.bool, device=device)
        table = torch.tensor([t.support_plane is not None for t in targets], dtype=torch.bool, device=device)
        if not bool(table.any()):
            table = None
        if not boxes or not bool(mask.any()):
            boxes, mask = [], torch.zeros_like(mask)
            if table is None:
                return None
        lo = torch.tensor([b[0] for b in boxes], dtype=dtype, device=device).reshape(-1, 3)
        hi = torch.tensor([b[1] for b in boxes], dtype=dtype, device=device).reshape(-1, 3)
        lift = float(sphere_margin_m) + TABLE_CLEARANCE_M
        planes = None if table is None else torch.tensor(
            [(*t.support_plane[:3], t.support_plane[3] - lift) if t.support_plane is not None else (0.0, 0.0, 1.0, 0.0)
             for t in targets], dtype=dtype, device=device)
        return cls(lo, hi, mask, planes, table)

    def applies_to(self, k: int) -> bool:
        """Whether target ``k`` has any scenery (boxes or a table)."""
        return bool(self.on_target[k]) or (self.on_table is not None and bool(self.on_table[k]))

    def distance(self, object_index: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        """``(B, N)`` m: signed distance of points ``(B, N, 3)`` to the nearest box or below the
        table; +inf for the samples (``object_index`` ``(B,)``) on targets without either."""
        inf = torch.full(points.shape[:-1], torch.inf, dtype=points.dtype, device=points.device)
        d = inf
        if self.lo.shape[0]:
            box = box_distance(points, self.lo.to(points.dtype), self.hi.to(points.dtype)).amin(-1)
            d = torch.where(self.on_target[object_index][:, None], box, inf)
        if self.planes is not None:
            below = plane_distance(points, self.planes.to(points.dtype)[object_index][:, None])
            d = torch.minimum(d, torch.where(self.on_table[object_index][:, None], below, inf))
        return d

    def penetration(self, object_index: torch.Tensor, centres: torch.Tensor, reach: torch.Tensor) -> torch.Tensor:
        """``(B, S)`` m: ``max(0, reach - sd)`` of sphere centres ``(B, S, 3)``, reach ``(S,)`` m."""
        return torch.relu(reach - self.distance(object_index, centres))

    def clear_of(self, points: torch.Tensor, clearance_m: float, k: int) -> torch.Tensor:
        """``(N,)`` bool: points ``(N, 3)`` m at least ``clearance_m`` outside target ``k``'s boxes
        and above its table."""
        index = torch.full((1,), k, dtype=torch.long, device=points.device)
        return self.distance(index, points[None])[0] >= clearance_m
