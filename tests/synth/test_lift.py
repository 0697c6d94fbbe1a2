"""The lift term of tabletop synthesis (energies.py ``E_lift``, select.py's lift epsilon), on a box
20 mm half-size resting on a table (up +z, centre of mass at its centre), against hand-computed
cases: a side pinch can lift it through friction, fingers pressing down on its top face cannot."""

from __future__ import annotations

import torch

from datagen.synth.config import EnergyWeights, SynthConfig
from datagen.synth.energies import lift_energy, lift_wrench
from datagen.synth.select import link_epsilon
from datagen.wrench import sample_directions

H = 0.02  # box half-size, m
UP = torch.tensor([[0.0, 0.0, 1.0]], dtype=torch.float64)
COM = torch.zeros(1, 3, dtype=torch.float64)


def side_pinch():
    """Two contacts on opposite side faces at mid-height, normals horizontal and inward."""
    p = torch.tensor([[[H, 0.0, 0.0], [-H, 0.0, 0.0]]], dtype=torch.float64)
    n = torch.tensor([[[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]], dtype=torch.float64)
    return p, n


def top_press():
    """Two contacts on the top face, normals straight down (the failures' contacts, flattened)."""
    p = torch.tensor([[[H / 2, 0.0, H], [-H / 2, 0.0, H]]], dtype=torch.float64)
    n = torch.tensor([[[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]]], dtype=torch.float64)
    return p, n


def cfg():
    return SynthConfig(weights=EnergyWeights(lift=1.0), sphere_margin_m=0.0)


def test_lift_wrench_is_the_up_force_at_the_com():
    # the centre of mass at the contacts' centroid: no lever arm, the wrench is the pure up force
    p, _ = side_pinch()
    w = lift_wrench(UP, COM, p)
    assert torch.allclose(w, torch.tensor([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]], dtype=torch.float64))
    # a centre of mass 20 mm to the side of the contacts (CPN length 20 mm): torque (com - c) x f / d
    w = lift_wrench(UP, torch.tensor([[0.0, H, 0.0]], dtype=torch.float64), p)
    expect = torch.tensor([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]], dtype=torch.float64) / 2 ** 0.5
    assert torch.allclose(w, expect)
    # a floating target (up 0) falls back to the object frame's z
    assert torch.allclose(lift_wrench(torch.zeros(1, 3, dtype=torch.float64), COM, p), lift_wrench(UP, COM, p))


def test_side_pinch_can_lift_and_pressing_down_cannot():
    """Hand-computed lift epsilon (gamma 0: how far the GWS reaches along the up force): each side
    contact's cone (normal force <= 1) gives at most mu = 0.5 upward with its normal forces and
    torques cancelling, so 2 x 0.5 = 1; a cone about a downward normal has no upward force."""
    mu = 0.5
    for (p, n), expect in ((side_pinch(), 1.0), (top_press(), 0.0)):
        w = torch.cat([UP, torch.zeros_like(UP)], -1)
        eps = link_epsilon(p, n, torch.ones(1, 2, dtype=torch.bool), mu, task=(w, 0.0), task_origin=COM)
        assert abs(float(eps) - expect) < 2e-3, (expect, float(eps))


def test_lift_energy_prefers_the_side_pinch():
    c = cfg()
    d = sample_directions(200, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    e_side = lift_energy(*side_pinch(), None, c, (UP, COM), d)
    e_top = lift_energy(*top_press(), None, c, (UP, COM), d)
    assert float(e_side) < float(e_top) - 0.1, (float(e_side), float(e_top))
    # masked for a floating target
    e_float = lift_energy(*side_pinch(), None, c, (torch.zeros(1, 3, dtype=torch.float64), COM), d)
    assert float(e_float) == 0.0
    # it has a gradient through the contacts' normals on the pressing-down grasp
    p, n = top_press()
    n = n.clone().requires_grad_(True)
    lift_energy(p, n, None, c, (UP, COM), d).sum().backward()
    assert float(n.grad.abs().sum()) > 0
