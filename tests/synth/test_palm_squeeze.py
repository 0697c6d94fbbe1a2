"""A power grasp's palm pressed in at the squeeze (``squeeze_palm_m``): the root's move, the
fingertips left where a fixed root puts them."""

import dataclasses

import numpy as np
import pytest
import torch
import trimesh

from datagen.errors import ConfigError
from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.energies import contact_sphere_index
from datagen.synth.links import link_contacts
from datagen.tasks import load_task


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


def test_the_squeeze_moves_the_palm_in_by_its_gap_and_keeps_the_fingertips(hand, tmp_path):
    mesh = trimesh.creation.icosphere(3)
    mesh.apply_scale(1 / np.sqrt(3))
    ball = GraspTarget.from_mesh(mesh, 0.12, "ball", grid_resolution=32)
    wrap = tmp_path / "wrap.yaml"
    wrap.write_text("name: wrap\ncontacts: {palm: pull, phalanges: candidate}\ninit: {kind: wrap, curl: 0.3}\n")
    cfg = SynthConfig(iters=30, num_directions=16, seed=3, grasp_type=str(wrap))
    task = load_task("force_closure")
    fixed = synthesize(hand, [ball], task, cfg, 4)
    pressed = synthesize(hand, [ball], task, dataclasses.replace(cfg, squeeze_palm_m=0.003), 4)
    assert torch.equal(fixed.grasp, pressed.grasp)  # the synthesis is the same
    g = pressed.grasp
    margin = hand.sphere_margin_m
    c, r = hand.spheres(g[:, :7], g[:, 7:])
    gap = link_contacts(hand, [ball], torch.zeros(4, dtype=torch.long), c, r, torch.tensor([hand.palm_link])).gap[:, 0] + margin
    d = torch.where(gap <= 0.01, gap.clamp_min(0) + 0.003, torch.zeros_like(gap))
    a = hand.palm_frame(g[:, :7], g[:, 7:]).approach
    assert torch.allclose(pressed.squeeze[:, :3] - g[:, :3], d[:, None] * a, atol=1e-6)
    assert torch.allclose(pressed.pregrasp[:, :3] - g[:, :3], -d[:, None] * a, atol=1e-6)
    assert torch.equal(fixed.squeeze[:, :7], g[:, :7])  # off: the root stays
    ts = contact_sphere_index(hand)
    tips = [hand.spheres(p[:, :7], p[:, 7:])[0][:, ts] for p in (fixed.squeeze, pressed.squeeze)]
    moved = (tips[1] - tips[0]).norm(dim=-1)  # (4, F) m
    assert bool((moved[:, 1:] < 0.6 * d[:, None]).all())  # the fingers undo most of the root's move


def test_a_palm_squeeze_of_a_centimetre_or_more_is_refused():
    with pytest.raises(ConfigError, match=r"squeeze_palm_m must be in \[0, 0.01\) m"):
        SynthConfig(squeeze_palm_m=0.01)
