"""Grasp types in synthesis: the power type's palm and phalanges, the per-size mix, the rows."""

import dataclasses

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.pipeline import synthesize_rows
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.links import link_contacts
from datagen.tasks import GraspMix, load_task


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


@pytest.fixture(scope="module")
def balls():
    mesh = trimesh.creation.icosphere(3)
    mesh.apply_scale(1 / np.sqrt(3))  # half the bounding-box diagonal: 1
    return [GraspTarget.from_mesh(mesh.copy(), s, f"ball{s}", grid_resolution=32) for s in (0.06, 0.12)]


CFG = SynthConfig(iters=60, seeds_per_grasp=1, num_directions=16, seed=3)


def _palm_gap(hand, target, grasp):
    c, r = hand.spheres(grasp[:, :7], grasp[:, 7:])
    lc = link_contacts(hand, [target], torch.zeros(len(grasp), dtype=torch.long), c, r, torch.tensor([hand.palm_link]))
    return lc.gap[:, 0]


@pytest.mark.slow
def test_power_grasp_pulls_the_palm_onto_the_object(hand, balls, tmp_path):
    """Same initial poses (same seed): every power grasp ends with the palm nearer the ball than
    the fingertip grasp from the same start (after 60 iterations, -0.6-2.0 mm against 0.1-3.0 mm).
    A type's ``init`` (here a pre-curl) starts from the same roots with its own joints."""
    from datagen.synth.init import curled_joints

    task = load_task("force_closure")
    big = balls[1:]  # radius 6.9 cm
    prec = synthesize(hand, big, task, CFG, 4)
    open_power = tmp_path / "power_open.yaml"
    open_power.write_text("name: power_open\ncontacts: {palm: pull, phalanges: candidate}\n")
    power = synthesize(hand, big, task, dataclasses.replace(CFG, grasp_type=str(open_power)), 4)
    assert torch.equal(prec.initial, power.initial)
    assert prec.grasp_type == "precision" and power.grasp_type == "power_open"
    curled = tmp_path / "power_curled.yaml"  # a type's init: the same roots, the fingers pre-curled
    curled.write_text("name: power_curled\ncontacts: {palm: pull, phalanges: candidate}\ninit: {curl: 0.3}\n")
    c = synthesize(hand, big, task, dataclasses.replace(CFG, grasp_type=str(curled), iters=1), 4)
    assert torch.equal(c.initial[:, :7], prec.initial[:, :7]) and c.grasp_type == "power_curled"
    assert torch.allclose(c.initial[:, 7:], curled_joints(hand, 0.3).expand(4, -1))
    g_prec, g_pow = _palm_gap(hand, big[0], prec.grasp), _palm_gap(hand, big[0], power.grasp)
    assert bool((g_pow < g_prec).all()) and float(g_pow.median()) < 0.002
    assert "link_distance" in power.energies and "link_distance" not in prec.energies


@pytest.mark.slow
def test_mix_by_size_gives_each_scale_its_type_and_keeps_the_fingertip_rows(hand, balls):
    task = load_task("force_closure")
    mix = GraspMix.from_dict({"bands": [{"max_scale_m": 0.09, "mix": {"precision": 1}}, {"mix": {"power": 1}}]})
    results, table = synthesize_rows(hand, balls, task, CFG, 2, grasp_types=mix)
    rows = table.to_pydict()
    assert [r.grasp_type for r in results] == ["precision", "power"]
    assert [(round(s, 3), k) for s, k in zip(rows["object_scale_m"], rows["grasp_type"])] == \
        [(0.06, "precision")] * 2 + [(0.12, "power")] * 2
    assert len(set(rows["grasp_id"])) == 4
    # the fingertip rows are those of a fingertip-only run on the small ball alone (same seed)
    _, alone = synthesize_rows(hand, balls[:1], task, CFG, 2)
    assert alone.column("grasp_id").to_pylist() == rows["grasp_id"][:2]
    assert np.array_equal(np.asarray(alone.column("grasp_qpos").to_pylist()), np.asarray(rows["grasp_qpos"][:2]))
    # a task naming its own fingertips keeps its own contact set, whatever the mix
    pinch = dataclasses.replace(task, name="pinch", fingers=("th", "ff"))
    res, tb = synthesize_rows(hand, balls[1:], pinch, CFG, 1, grasp_types=mix)
    assert tb.column("grasp_type").to_pylist() == ["task"]


@pytest.mark.slow
def test_a_types_hands_entry_reaches_that_hands_initial_poses(hand, balls, tmp_path):
    """``hands.shadow.init`` pre-curls Shadow's fingers (the joints `curled_joints` gives), from the
    same roots as the type without it; an entry for another hand leaves Shadow's start open."""
    from datagen.synth.init import curled_joints

    task, cfg = load_task("force_closure"), dataclasses.replace(CFG, iters=1)
    base = tmp_path / "grip.yaml"
    base.write_text("name: grip\ncontacts: {palm: pull}\n")
    own, other = tmp_path / "grip_own.yaml", tmp_path / "grip_other.yaml"
    own.write_text("name: grip_own\ncontacts: {palm: pull}\nhands: {shadow: {init: {curl: 0.3}}}\n")
    other.write_text("name: grip_other\ncontacts: {palm: pull}\nhands: {leap: {init: {curl: 0.3}}}\n")
    b, o, x = (synthesize(hand, balls[1:], task, dataclasses.replace(cfg, grasp_type=str(p)), 3)
               for p in (base, own, other))
    assert torch.equal(o.initial[:, :7], b.initial[:, :7]) and torch.equal(x.initial, b.initial)
    assert torch.allclose(o.initial[:, 7:], curled_joints(hand, 0.3).expand(3, -1))
    assert not torch.allclose(b.initial[:, 7:], o.initial[:, 7:])
