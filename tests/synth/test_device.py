"""The CUDA path against the CPU one (skipped without a GPU).

The reference is the CPU run of the same code on the same inputs: every energy term and its
gradient at the same poses must agree to float32 rounding, a whole synthesis (multi-start, squeeze,
epsilon) must run on the GPU and return tensors there, and the same seed must give the same result
twice on the GPU (the project's determinism promise, which atomics-based CUDA kernels can break).
"""

import numpy as np
import pytest
import torch
import trimesh

from datagen.hands import load_hand
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.energies import contact_sphere_index, evaluate_state, hand_object_state
from datagen.tasks import load_task
from datagen.wrench import sample_directions

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")


@pytest.fixture(scope="module")
def target():
    mesh = trimesh.creation.cylinder(radius=0.35, height=1.0, sections=48)
    mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))
    return GraspTarget.from_mesh(mesh, 0.08, "cylinder", grid_resolution=32)


@pytest.fixture(scope="module")
def poses(target):
    """Poses 60 iterations into a CPU synthesis: touching, some penetrating (every term non-zero)."""
    res = synthesize(load_hand("shadow"), [target], load_task("force_closure"), SynthConfig(iters=60, seed=3), 32)
    return res.grasp


def _terms_and_grads(device: str, target, task_name: str, poses):
    hand = load_hand("shadow", device=device)
    task = load_task(task_name)
    cfg = SynthConfig(seed=0).for_hand(hand)
    tgt = target if device == "cpu" else target.to(device)
    index = torch.zeros(poses.shape[0], dtype=torch.long, device=device)
    root, joints = poses[:, :7].to(device), poses[:, 7:].to(device)
    tips = contact_sphere_index(hand)
    dirs = sample_directions(cfg.num_directions, generator=torch.Generator().manual_seed(4), device=device)
    root = root.clone().requires_grad_(True)
    joints = hand.apply_couplings(joints).clone().requires_grad_(True)
    state = hand_object_state(hand, [tgt], index, root, joints, tips, exact_contacts=cfg.exact_contacts,
                              sphere_margin=cfg.sphere_margin_m, self_collision=True)
    terms = evaluate_state(state, cfg, task, dirs)
    terms.total.sum().backward()
    values = {k: v.detach().cpu() for k, v in terms.as_dict().items()}
    return values, root.grad.cpu(), joints.grad.cpu()


@pytest.mark.parametrize("task_name", ["force_closure", "turn_knob3"])
def test_energy_terms_and_gradients_match_cpu(target, poses, task_name):
    cpu, g_root_c, g_joint_c = _terms_and_grads("cpu", target, task_name, poses)
    gpu, g_root_g, g_joint_g = _terms_and_grads("cuda", target, task_name, poses)
    assert cpu.keys() == gpu.keys()
    for k in cpu:
        scale = cpu[k].abs().max().clamp_min(1e-3)
        assert torch.allclose(cpu[k], gpu[k], atol=1e-4 * scale, rtol=1e-4), k
    for c, g in ((g_root_c, g_root_g), (g_joint_c, g_joint_g)):
        scale = c.abs().max().clamp_min(1e-3)
        assert torch.allclose(c, g, atol=1e-3 * scale, rtol=1e-3)


def test_energy_terms_and_gradients_repeat_on_the_gpu(target, poses):
    """Three evaluations at the same poses give the same bits, term by term: a failure names the
    term whose CUDA kernels sum in thread order (atomic adds: `index_add_`, `index_select`'s
    gradient; `datagen.scatter` has the fixed-order replacements)."""
    runs = [_terms_and_grads("cuda", target, "force_closure", poses) for _ in range(3)]
    for k in runs[0][0]:
        assert all(torch.equal(runs[0][0][k], r[0][k]) for r in runs[1:]), k
    for i, name in ((1, "root gradient"), (2, "joint gradient")):
        assert all(torch.equal(runs[0][i], r[i]) for r in runs[1:]), name


def test_synthesis_runs_on_the_gpu_and_repeats(target):
    hand = load_hand("shadow", device="cuda")
    cfg = SynthConfig(iters=80, seed=5, seeds_per_grasp=4, seed_select_iter=40)
    a = synthesize(hand, [target.to("cuda")], load_task("force_closure"), cfg, 6)
    b = synthesize(hand, [target.to("cuda")], load_task("force_closure"), cfg, 6)
    for name in ("grasp", "pregrasp", "squeeze", "contact_points", "epsilon", "max_penetration"):
        t = getattr(a, name)
        assert t.device.type == "cuda", name
        assert torch.isfinite(t).all(), name
        assert torch.equal(t, getattr(b, name)), f"{name} differs between two runs with the same seed"
    # the poses touch the object (the same bar as the CPU synthesis tests)
    assert (a.tip_distance.abs().amax(-1) <= 0.01).float().mean() >= 0.5
