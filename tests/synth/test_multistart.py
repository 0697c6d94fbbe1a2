"""Multi-start synthesis (``seeds_per_grasp``) and the optimizer's continued step schedule."""

import math

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.energies import contact_sphere_index, hand_object_state
from datagen.synth.init import initial_poses
from datagen.synth.optimizer import GroupedDescent, PoseVariables
from datagen.synth.synthesize import _best_seeds
from datagen.tasks import load_task
from datagen.wrench import epsilon_metric


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


@pytest.fixture(scope="module")
def box():
    mesh = trimesh.creation.box(extents=[1.0, 0.7, 1.4])
    mesh.apply_scale(1.0 / np.linalg.norm(0.5 * mesh.extents))
    return GraspTarget.from_mesh(mesh, 0.07, "box", grid_resolution=32)


def test_continued_schedule_starts_with_the_decayed_step():
    """A linear energy E = x: every step is accepted, the normalized gradient is 1, the momentum
    m <- (0.9 m + 1) / 2 starts at 0, so iteration k moves x by -step_t * decay^(k // every) * m_k.
    Started at iteration 100 (every 50, decay 0.5) the first move is step_t * 0.25 * 0.5."""
    opt = GroupedDescent([torch.tensor([0])], (0.01, 0.0, 0.0), momentum=0.9, step_decay=0.5, decay_every=50)

    def energy(t, q, j):
        return t[:, 0] + 0 * q.sum(-1) + 0 * j.sum(-1), {}

    x0 = PoseVariables(torch.zeros(1, 3), torch.tensor([[1.0, 0, 0, 0]]), torch.zeros(1, 1))
    x, _, _ = opt.run(energy, x0, 1, first_iter=100)
    assert math.isclose(float(x.translation[0, 0]), -0.01 * 0.25 * 0.5, rel_tol=1e-6)
    x, _, _ = opt.run(energy, x0, 2, first_iter=99)  # iteration 99 at 0.5, iteration 100 decays to 0.25
    assert math.isclose(float(x.translation[0, 0]), -0.01 * (0.5 * 0.5 + 0.25 * 0.725), rel_tol=1e-6)


def test_best_seed_has_the_largest_epsilon_of_its_group(hand, box):
    """_best_seeds keeps, per grasp, a seed whose fingertip contacts have the largest epsilon
    (checked seed by seed with the public epsilon metric), or the lowest energy on a tie."""
    cfg = SynthConfig()
    task = load_task("force_closure")
    S, B = 4, 3
    index = torch.zeros(B * S, dtype=torch.long)
    # short descent so that contacts exist and epsilons differ
    res = synthesize(hand, [box], task, SynthConfig(iters=60, seed=2), B * S)
    x = PoseVariables(res.grasp[:, :3], res.grasp[:, 3:7], res.grasp[:, 7:])
    energy = torch.linspace(0.0, 1.0, B * S)
    tips = contact_sphere_index(hand)
    best = _best_seeds(hand, [box], index, x, energy, tips, task, cfg, S)
    st = hand_object_state(hand, [box], index, x.root_pose(), hand.apply_couplings(x.joints), tips,
                           sphere_margin=cfg.sphere_margin_m, self_collision=False)
    eps = epsilon_metric(st.contact_points.double(), st.contact_normals.double(), cfg.mu)
    usable = st.tip_distance.abs().amax(-1) <= cfg.contact_threshold_m
    eps = torch.where(usable, eps, torch.zeros_like(eps)).reshape(B, S)
    assert best.shape == (B,)
    for b in range(B):
        k = int(best[b]) - b * S
        assert 0 <= k < S
        assert float(eps[b, k]) >= float(eps[b].max()) - 1e-6
        ties = (eps[b] >= eps[b].max() - 1e-6).nonzero().squeeze(-1)
        assert k == int(ties.min())  # energy increases with the row: the first tie has the lowest


@pytest.mark.slow
def test_multistart_outputs_one_grasp_per_slot_and_raises_epsilon(hand, box):
    """Same number of rows; each output starts from one of its own slot's seeds; with 6 seeds
    the grasps' epsilon is at least that of single starts on average (same object and budget)."""
    task = load_task("force_closure")
    one = synthesize(hand, [box], task, SynthConfig(iters=120, seed=5), 6)
    many = synthesize(hand, [box], task, SynthConfig(iters=120, seed=5, seeds_per_grasp=6, seed_select_iter=60), 6)
    assert many.grasp.shape == one.grasp.shape and many.epsilon.shape == (6,)
    gen = torch.Generator().manual_seed(5)
    index = torch.zeros(36, dtype=torch.long)
    root, joints = initial_poses(hand, [box], index, task.init, gen)
    starts = torch.cat([root, hand.apply_couplings(joints)], -1).reshape(6, 6, -1)
    for b in range(6):
        assert torch.isclose(starts[b], many.initial[b]).all(-1).any(), f"slot {b} did not start from its seeds"
    assert float(many.epsilon.mean()) >= float(one.epsilon.mean())
    assert int((many.epsilon > 0).sum()) >= int((one.epsilon > 0).sum())
