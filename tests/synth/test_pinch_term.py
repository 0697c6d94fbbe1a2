"""Where synthesis adds the pinch's antipodal error to E_t (`SynthConfig.pinch_antipodal`): two
task fingers at gamma = 180 deg with the task energy on; nowhere else."""

import dataclasses
import math

import torch

from datagen.synth import SynthConfig
from datagen.synth.energies import HandObjectState, evaluate_state
from datagen.tasks import load_task
from datagen.wrench import pinch_antipodal_error, sample_directions


def _state(m: int) -> HandObjectState:
    """Two poses, ``m`` contacts; the first two a pinch on the z axis, contact 0's normal turned 0.3 rad."""
    pts = torch.zeros(2, m, 3)
    pts[:, 1, 2] = 0.05
    nrm = torch.zeros(2, m, 3)
    nrm[:, 0] = torch.tensor([0.0, -math.sin(0.3), math.cos(0.3)])
    nrm[:, 1] = torch.tensor([0.0, 0.0, -1.0])
    if m > 2:
        pts[:, 2] = torch.tensor([0.03, 0.0, 0.025])
        nrm[:, 2] = torch.tensor([-1.0, 0.0, 0.0])
    z = torch.zeros(2)
    return HandObjectState(tips=pts.clone(), tip_distance=torch.zeros(2, m), contact_points=pts, contact_normals=nrm,
                           sphere_penetration=z, max_penetration=z, self_penetration=z, joint_violation=z)


def test_the_term_enters_e_task_only_for_a_two_finger_closure_task():
    dirs = sample_directions(16, generator=torch.Generator().manual_seed(0))
    key, knob = load_task("precision_key"), load_task("turn_knob3")  # gamma 180 / a sector
    assert key.gamma_deg >= 180 and knob.gamma_deg < 180
    off = SynthConfig(sphere_margin_m=0.0)
    on = dataclasses.replace(off, pinch_antipodal=2.0)
    s2, s3 = _state(2), _state(3)
    err = pinch_antipodal_error(s2.contact_points, s2.contact_normals)
    assert torch.allclose(err, torch.full((2,), 1 - math.cos(0.3)))
    base, with_term = evaluate_state(s2, off, key, dirs), evaluate_state(s2, on, key, dirs)
    assert torch.allclose(with_term.task - base.task, 2.0 * err)
    assert torch.allclose(with_term.total - base.total, off.weights.task * 2.0 * err)
    # three contacts, a task with a sector, or the task energy off (the baseline): unchanged
    assert torch.equal(evaluate_state(s3, on, key, dirs).total, evaluate_state(s3, off, key, dirs).total)
    assert torch.equal(evaluate_state(s2, on, knob, dirs).total, evaluate_state(s2, off, knob, dirs).total)
    no_task = dataclasses.replace(on, weights=dataclasses.replace(on.weights, task=0.0))
    assert torch.equal(evaluate_state(s2, no_task, key, dirs).total,
                       evaluate_state(s2, dataclasses.replace(no_task, pinch_antipodal=0.0), key, dirs).total)
