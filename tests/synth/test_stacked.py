"""The stacked grid queries (`datagen.synth.stacked`) against each target's own query: the same
distances, closest points, normals and gradients bit for bit, on every device; None where the
layout or the grids do not allow stacking (the caller then loops over the targets)."""

from __future__ import annotations

import pytest
import torch

from datagen.synth.stacked import grid_distance, grid_query

from ..conftest import DEVICES
from .grids import grid_targets as _targets


def _points(n: int, device) -> torch.Tensor:
    g = torch.Generator().manual_seed(3)
    return (torch.rand(3 * n, 5, 3, generator=g) * 0.16 - 0.08).to(device).requires_grad_(True)


@pytest.mark.parametrize("device", DEVICES)
def test_stacked_queries_equal_each_targets_own(device):
    targets = [t.to(device) for t in _targets()]
    index = torch.arange(3, device=device).repeat_interleave(4)
    pts = _points(4, device)
    d = grid_distance(targets, index, pts)
    dq, c, n = grid_query(targets, index, pts)
    (d.sum() + (dq * 2).sum() + (c ** 2).sum()).backward()
    got_grad = pts.grad.clone()
    pts.grad = None
    ref_d, ref_dq, ref_c, ref_n = [], [], [], []
    for k, t in enumerate(targets):
        rows = pts[4 * k:4 * k + 4]
        ref_d.append(t.distance(rows))
        a, b, m = t.approx_query(rows)
        ref_dq.append(a), ref_c.append(b), ref_n.append(m)
    ref = [torch.cat(x) for x in (ref_d, ref_dq, ref_c, ref_n)]
    (ref[0].sum() + (ref[1] * 2).sum() + (ref[2] ** 2).sum()).backward()
    for a, b in zip((d, dq, c, n), ref):
        assert torch.equal(a, b)
    assert torch.equal(got_grad, pts.grad)
    assert float(d.detach().abs().max()) > 0  # points around the objects: a real check, not zeros


def test_no_stacking_where_the_layout_or_the_grids_differ():
    targets = _targets()
    pts = _points(4, "cpu")
    shuffled = torch.tensor([0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2])
    assert grid_distance(targets, shuffled, pts) is None and grid_query(targets, shuffled, pts) is None
    assert grid_distance(targets[:1], torch.zeros(12, dtype=torch.long), pts) is None  # one target: no gain
    mixed = _targets((24, 32, 24))
    assert grid_distance(mixed, torch.arange(3).repeat_interleave(4), pts) is None


def test_grid_normals_are_the_central_differences_of_the_grid_distance():
    """`GraspTarget.approx_query` queries the six offset points at once: its normals equal the
    normalized differences of single-axis grid queries one cell apart, bit for bit."""
    t = _targets()[0]
    pts = _points(2, "cpu").detach()
    g = t.grid
    h = float(((g.hi - g.lo) / (g.values.shape[0] - 1)).max()) * t.scale
    axis = torch.eye(3) * h
    diff = torch.stack([t.distance(pts + axis[k]) - t.distance(pts - axis[k]) for k in range(3)], dim=-1)
    _, _, n = t.approx_query(pts)
    assert torch.equal(n, diff / diff.norm(dim=-1, keepdim=True).clamp_min(1e-12))
    assert float(diff.abs().max()) > 0
