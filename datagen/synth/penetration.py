"""Collision-sphere penetration of the objects, sampling the SDF grid only where it can be non-zero.

``E_pen`` sums ``max(0, reach_s - d(c_s))^2`` over every collision sphere of every pose
(``reach`` = radius minus the allowed sink, m). Most spheres are nowhere near the object: in a
force-closure synthesis about 88% of Shadow's 429 sphere centres lie outside the object's SDF grid
box for the whole run. Outside the box a grid distance is the grid value at the nearest boundary
point plus the distance to the box (`GridSDF.distance`), so it is at least ``scale * (floor +
outside)``, ``floor`` the least value on the grid's six faces. A sphere whose bound already
exceeds its reach cannot penetrate: its term is exactly 0 with a zero gradient, whatever the grid
says. Only the others are sampled, with the same per-point arithmetic as a query of every point
(`datagen.synth.stacked` for a stacked batch, the target's own grid otherwise), so the terms, their
sums and their gradients are bit for bit those of querying every sphere.
"""

from __future__ import annotations

from collections import OrderedDict

import torch

from datagen.scatter import batch_rows
from datagen.synth.stacked import per_target_rows, stacked_distance, stacked_grids

__all__ = ["sphere_penetration"]

_TOLERANCE = 1e-4  #: normalized units taken off the bound (interpolation rounding at the box faces)
_BOUNDS: OrderedDict = OrderedDict()  # (target ids, dtype, device) -> (targets, bounds); the last two batches


def _grid_bounds(targets, dtype, device) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per target: box ``lo``, ``hi`` ``(T, 3)`` (normalized), ``scale`` ``(T,)`` m and ``floor``
    ``(T,)`` (normalized; -inf for a target without a grid: every point is a candidate)."""
    key = (tuple(id(t) for t in targets), dtype, str(device))
    hit = _BOUNDS.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], targets)):
        return hit[1]
    lo, hi, scale, floor = [], [], [], []
    for t in targets:
        g = t.grid
        if g is None:
            lo.append(torch.zeros(3)), hi.append(torch.zeros(3)), floor.append(float("-inf"))
        else:
            lo.append(g.lo.cpu()), hi.append(g.hi.cpu()), floor.append(g.boundary_floor())
        scale.append(t.scale)
    as_t = lambda x: torch.as_tensor(x, dtype=dtype).to(device)  # noqa: E731
    bounds = as_t(torch.stack(lo)), as_t(torch.stack(hi)), as_t(scale), as_t(floor)
    _BOUNDS[key] = (tuple(targets), bounds)
    while len(_BOUNDS) > 2:
        _BOUNDS.popitem(last=False)
    return bounds


def _candidates(targets, object_index: torch.Tensor, centres: torch.Tensor, reach: torch.Tensor) -> torch.Tensor:
    """Flat indices into ``(B, S)`` of the sphere centres ``(B, S, 3)`` m whose grid distance may
    be below their ``reach`` ``(S,)`` m."""
    lo, hi, scale, floor = (x[object_index] for x in _grid_bounds(targets, centres.dtype, centres.device))
    q = centres / scale[:, None, None]
    outside = (q - torch.maximum(torch.minimum(q, hi[:, None]), lo[:, None])).norm(dim=-1)  # (B, S)
    # inside the box (outside == 0) nothing is known: every such point is a candidate
    lower = torch.where(outside > 0, scale[:, None] * (floor[:, None] + outside - _TOLERANCE),
                        torch.full_like(outside, -torch.inf))
    return (lower < reach).reshape(-1).nonzero().squeeze(-1)


def _stacked_candidate_distance(targets, n: int, N: int, points: torch.Tensor, idx: torch.Tensor) -> torch.Tensor | None:
    """Grid distances ``(C,)`` of the candidate points ``idx`` of a stacked batch (``n`` poses per
    target, ``N`` points per pose), one padded ``grid_sample`` for all targets; None if the
    targets' grids cannot be stacked."""
    stack = stacked_grids(targets, points.dtype)
    if stack is None:
        return None
    T, P = len(targets), n * N
    t = torch.div(idx, P, rounding_mode="floor")
    counts = torch.bincount(t, minlength=T)
    slot = torch.arange(idx.shape[0], device=idx.device) - (torch.cumsum(counts, 0) - counts)[t]
    width = int(counts.max())
    local = torch.zeros(T, width, dtype=torch.long, device=idx.device)
    local[t, slot] = idx - t * P
    padded = batch_rows(points.reshape(T, P, 3), local)  # (T, width, 3)
    return stacked_distance(stack, padded)[t, slot]


def sphere_penetration(targets, object_index: torch.Tensor, centres: torch.Tensor, reach: torch.Tensor) -> torch.Tensor:
    """``(B, S)`` penetration ``max(0, reach - d)`` (m) of sphere centres ``(B, S, 3)`` m in the
    objects ``targets[object_index]`` ``(B,)``, ``reach`` ``(S,)`` m; ``d`` the grid distance."""
    B, S, _ = centres.shape
    flat = centres.reshape(-1, 3)
    r = reach.expand(B, S).reshape(-1)
    with torch.no_grad():
        idx = _candidates(targets, object_index, centres.detach(), reach)
    pen = centres.new_zeros(B * S)
    if idx.numel() == 0:
        return pen.reshape(B, S)
    n = per_target_rows(targets, object_index)
    d = _stacked_candidate_distance(targets, n, S, flat, idx) if n else None
    if d is None:  # each target's own grid on its candidates
        d = centres.new_zeros(idx.shape[0])
        which = object_index[torch.div(idx, S, rounding_mode="floor")]
        for k, target in enumerate(targets):
            sel = (which == k).nonzero().squeeze(-1)
            if sel.numel():
                d = d.index_copy(0, sel, target.distance(flat[idx[sel]]).to(centres.dtype))
    return pen.index_copy(0, idx, torch.relu(r[idx] - d)).reshape(B, S)
