"""`datagen.synth.penetration.sphere_penetration` against querying every sphere of every pose
(``max(0, reach - target.distance(c))`` per target, the term before pruning): the same values and
gradients bit for bit, on every device and batch layout, while most spheres are not sampled; and
the grid-box bound it prunes with (`GridSDF.boundary_floor`) checked on the grid itself."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from datagen.synth.penetration import _candidates, sphere_penetration

from ..conftest import DEVICES
from .grids import grid_targets as _targets


def _spheres(B: int, S: int, device, spread: float = 0.3):
    """Centres ``(B, S, 3)`` m scattered up to ``spread`` m around the objects, reach ``(S,)`` m."""
    g = torch.Generator().manual_seed(5)
    c = ((torch.rand(B, S, 3, generator=g) - 0.5) * spread).to(device).requires_grad_(True)
    reach = (torch.rand(S, generator=g) * 0.012).to(device)
    return c, reach


def _reference(targets, index, c, reach):
    d = torch.stack([targets[int(k)].distance(c[b]) for b, k in enumerate(index.tolist())])
    return torch.relu(reach - d)


def _check(targets, index, device):
    c, reach = _spheres(index.shape[0], 200, device)
    got = sphere_penetration(targets, index, c, reach)
    (got * got * 3).sum().backward()
    g_got, c.grad = c.grad.clone(), None
    ref = _reference(targets, index, c, reach)
    (ref * ref * 3).sum().backward()
    assert torch.equal(got, ref)
    assert torch.equal(g_got, c.grad)
    assert int((ref > 0).sum()) > 20  # spheres do penetrate: a real check, not zeros
    sampled = _candidates(targets, index, c.detach(), reach).numel()
    assert sampled < 0.5 * c.shape[0] * c.shape[1]  # most spheres were never sampled


@pytest.mark.parametrize("device", DEVICES)
def test_same_as_every_sphere_queried_stacked_batch(device):
    targets = [t.to(device) for t in _targets()]
    _check(targets, torch.arange(3, device=device).repeat_interleave(4), device)


@pytest.mark.parametrize("device", DEVICES)
def test_same_as_every_sphere_queried_other_layouts(device):
    targets = [t.to(device) for t in _targets()]
    _check(targets[:1], torch.zeros(6, dtype=torch.long, device=device), device)  # one target
    _check(targets, torch.tensor([2, 0, 1, 0, 2, 1, 1, 0], device=device), device)  # interleaved rows
    mixed = [t.to(device) for t in _targets((16, 24, 20))]  # grids that cannot be stacked
    _check(mixed, torch.arange(3, device=device).repeat_interleave(3), device)


def test_target_without_grid_is_queried_everywhere():
    t = _targets()[:2]
    exact = [t[0], dataclasses.replace(t[1], grid=None)]  # exact mesh distances: no bound, no pruning
    index = torch.tensor([0, 0, 1, 1])
    c, reach = _spheres(4, 60, "cpu", spread=0.2)
    got = sphere_penetration(exact, index, c, reach)
    assert torch.equal(got, _reference(exact, index, c, reach))
    cand = _candidates(exact, index, c.detach(), reach)
    assert int((cand >= 2 * 60).sum()) == 2 * 60  # every point of target 1 (rows 2, 3) is sampled


def test_nothing_near_the_objects_is_zero():
    targets = _targets()
    c, reach = _spheres(3, 50, "cpu")
    far = (c.detach() + 5.0).requires_grad_(True)  # metres away from every grid box
    pen = sphere_penetration(targets, torch.arange(3), far, reach)
    assert pen.shape == (3, 50) and torch.equal(pen, torch.zeros(3, 50))


def test_boundary_floor_bounds_distances_outside_the_box():
    target = _targets()[1]
    grid = target.grid
    v = grid.values
    faces = torch.cat([v[[0, -1]].reshape(-1), v[:, [0, -1]].reshape(-1), v[:, :, [0, -1]].reshape(-1)])
    assert grid.boundary_floor() == float(faces.min())
    g = torch.Generator().manual_seed(2)
    p = (torch.rand(20000, 3, generator=g) - 0.5) * 6.0  # normalized units, most outside the box
    inside = torch.maximum(torch.minimum(p, grid.hi), grid.lo)
    outside = (p - inside).norm(dim=-1)
    d = grid.distance(p)  # scale 1
    sel = outside > 0
    assert int(sel.sum()) > 10000
    assert bool((d[sel] >= grid.boundary_floor() + outside[sel] - 1e-5).all())
