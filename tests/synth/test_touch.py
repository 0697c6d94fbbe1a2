"""touch_grasp: the task fingertips' real gaps (link collision surface, exact object distance)
against MuJoCo's own hand-object distances, before and after the fingertips are moved in."""

import dataclasses

import numpy as np
import pytest
import torch
import trimesh

from datagen.eval import EvalConfig, Evaluator
from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.touch import real_tip_gaps
from datagen.tasks import load_task
from tests.eval.grasps import box_pieces


def test_touch_closes_the_real_gaps_mujoco_measures(tmp_path):
    hand = load_hand("shadow")
    half = np.array([0.025, 0.035, 0.045])
    pieces = box_pieces(half, tmp_path)
    s = float(np.linalg.norm(half))
    target = GraspTarget.from_mesh(trimesh.creation.box(extents=2 * half / s), s, "box")
    task = load_task("force_closure")
    cfg = SynthConfig(iters=120, seeds_per_grasp=2, seed_select_iter=60, seed=0)
    plain = synthesize(hand, [target], task, cfg, 4)
    touched = synthesize(hand, [target], task, dataclasses.replace(cfg, touch_real_gaps=True), 4)
    tips = torch.arange(len(hand.fingertip_names))
    with Evaluator(hand, EvalConfig()) as ev:
        def mujoco_gaps(res):
            out = []
            for b in range(4):
                poses = torch.stack([res.pregrasp[b], res.grasp[b], res.squeeze[b]]).double().numpy()
                out.append(ev.evaluate(pieces, poses).finger_distance_m)
            return np.array(out)
        before, after = mujoco_gaps(plain), mujoco_gaps(touched)
    ours = real_tip_gaps(hand, [target], plain.object_index, plain.grasp[:, :7], plain.grasp[:, 7:], tips).numpy()
    near = before < 0.01  # fingertips that the synthesis put on the box (MuJoCo reports up to 50 mm)
    assert near.sum() >= 8
    # the same gaps as MuJoCo's, to within the spacing of the surface points on the curved pads
    assert np.abs(ours[near] - before[near]).max() < 5e-4
    # the spheres overshoot the pads: before the move the real fingertips stand off the box ...
    assert np.median(before[near]) > 3e-4
    # ... after it they touch it (MuJoCo distance within half a millimetre)
    assert np.abs(after[near]).max() < 6e-4, after[near]
