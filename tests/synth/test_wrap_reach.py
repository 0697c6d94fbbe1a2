"""A power grasp's reach term (``weights.wrap_reach``) against MuJoCo's kinematics and a box."""

import dataclasses

import mujoco
import numpy as np
import pytest
import torch
import trimesh

from datagen.errors import ConfigError
from datagen.hands import load_hand
from datagen.pipeline import resolve
from datagen.synth import GraspTarget, SynthConfig, synthesize
from datagen.synth.energies import contact_sphere_index, evaluate_state, hand_object_state, wrap_reach
from datagen.synth.init import initial_poses
from datagen.tasks import InitConfig, load_task

EXTENTS = np.array([0.14, 0.09, 0.06])  # the box, m


@pytest.fixture(scope="module")
def hand():
    return load_hand("shadow")


def _box(extents):
    """A box of ``extents`` (3,) m whose hull samples are its 8 corners (its exact extent along any axis)."""
    mesh = trimesh.creation.box(extents / np.linalg.norm(extents / 2))  # half its diagonal: 1 unit
    t = GraspTarget.from_mesh(mesh, float(np.linalg.norm(extents / 2)), "box", grid_resolution=32)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * extents / 2
    return dataclasses.replace(t, hull_points=torch.as_tensor(corners, dtype=torch.float32))


@pytest.fixture(scope="module")
def box():
    return _box(EXTENTS)


def _poses(hand, box, n=6):
    init = InitConfig(kind="wrap", curl=0.3, distance_m=(0.0, 0.02))
    root, q = initial_poses(hand, [box], torch.zeros(n, dtype=torch.long), init, torch.Generator().manual_seed(1))
    return root.double(), hand.apply_couplings(q).double()


def _mujoco_reach(hand, root, joints, tip_spheres):
    """The reach from MuJoCo's own forward kinematics (free root): the palm body's rotation times
    the spec's approach axis, each fingertip's contact-sphere centre, the box's corners."""
    spec = mujoco.MjSpec.from_file(str(hand.mjcf_path))
    spec.body(hand.link_names[0]).add_freejoint()
    model = spec.compile()
    data = mujoco.MjData(model)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * EXTENTS / 2
    out = []
    for b in range(len(root)):
        data.qpos[:7] = root[b].numpy()
        data.qpos[7:] = hand.joints_to_qpos(joints[b])
        mujoco.mj_kinematics(model, data)
        a = data.xmat[model.body(hand.link_names[hand.palm_link]).id].reshape(3, 3) @ np.asarray(hand.spec.palm.approach)
        tips = []
        for s in tip_spheres.tolist():
            body = model.body(hand.link_names[int(hand.sphere_link_index[s])]).id
            tips.append(data.xmat[body].reshape(3, 3) @ hand.sphere_centres_local[s].double().numpy() + data.xpos[body])
        h = corners @ a
        out.append(max(np.asarray(tips) @ a) - 0.5 * (h.max() + h.min()))
    return np.array(out)


def test_reach_and_its_energy_match_mujoco_kinematics(hand, box):
    """``wrap_reach`` is MuJoCo's farthest fingertip along the palm's approach axis past the box's
    middle along it; ``E_reach`` adds ``w max(0, -r)^2`` to the total and nothing where r > 0."""
    hand64 = load_hand("shadow", dtype=torch.float64)
    root, joints = _poses(hand64, box)
    ts = contact_sphere_index(hand64)
    T = hand64.link_transforms(root, joints)
    centres, _ = hand64.spheres(root, joints, transforms=T)
    idx = torch.zeros(len(root), dtype=torch.long)
    r = wrap_reach(hand64, [box], idx, T, centres[:, ts])
    ref = _mujoco_reach(hand64, root, joints, ts)
    assert np.abs(r.numpy() - ref).max() < 1e-5
    assert (ref < 0).any()  # wrap starts stop on the near half (the term has work to do)
    shifted = dataclasses.replace(box, hull_points=box.hull_points + torch.tensor([0.0, 0.0, 0.01]))
    a = (T[:, hand64.palm_link, :3, :3] @ torch.tensor(hand64.spec.palm.approach, dtype=torch.float64))
    assert torch.allclose(wrap_reach(hand64, [shifted], idx, T, centres[:, ts]), r - 0.01 * a[:, 2], atol=1e-6)
    half = 0.5 * np.abs(EXTENTS @ np.abs(a.numpy().T))  # the box's half extent along each a
    assert np.allclose(wrap_reach(hand64, [box], idx, T, centres[:, ts], past=0.5).numpy(), ref - 0.5 * half, atol=1e-5)
    cfg = SynthConfig().for_hand(hand64)
    task = load_task("force_closure")
    dirs = torch.eye(6, dtype=torch.float64)
    state = hand_object_state(hand64, [box], idx, root, joints, ts, sphere_margin=cfg.sphere_margin_m, reach=0.0)
    off = evaluate_state(state, cfg, task, dirs)
    on = evaluate_state(state, dataclasses.replace(cfg, weights=dataclasses.replace(cfg.weights, wrap_reach=1e4)), task, dirs)
    want = 1e4 * np.maximum(0.0, -ref) ** 2
    assert np.allclose((on.total - off.total).numpy(), want, atol=1e-9)
    assert np.allclose(on.wrap_reach.numpy(), want / 1e4, atol=1e-12)


def test_a_negative_reach_weight_or_a_target_past_the_far_side_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="wrap_reach must be a finite number >= 0"):
        SynthConfig.from_dict({"weights": {"wrap_reach": -1.0}})
    bad = tmp_path / "far.yaml"  # a grasp type's synth block: refused when its recipe is built
    bad.write_text("name: far\ncontacts: {palm: pull}\nsynth: {wrap_reach_past: 1.5, weights: {wrap_reach: 10000}}\n")
    with pytest.raises(ConfigError, match=r"SynthConfig.wrap_reach_past must be in \[0, 1\)"):
        resolve("shadow", "force_closure", config={"grasp_types": str(bad)}).synth_for(str(bad))


@pytest.mark.slow
def test_the_reach_term_puts_a_fingertip_further_past_the_middle(hand, tmp_path):
    """Same starts (same seed) on a 16 x 14 x 12 cm box: with the term the farthest fingertip
    ends further past the box's middle along the palm's approach than without it, on average."""
    box = _box(np.array([0.16, 0.14, 0.12]))
    task = load_task("force_closure")
    wrap = tmp_path / "wrap.yaml"
    wrap.write_text("name: wrap\ncontacts: {palm: pull, phalanges: candidate}\ninit: {kind: wrap, curl: 0.3}\n")
    cfg = SynthConfig(iters=60, num_directions=16, seed=3, grasp_type=str(wrap))
    on = dataclasses.replace(cfg, weights=dataclasses.replace(cfg.weights, wrap_reach=1e4))
    results = [synthesize(hand, [box], task, c, 4) for c in (cfg, on)]
    assert torch.equal(results[0].initial, results[1].initial)
    reach = []
    for res in results:
        g = res.grasp
        T = hand.link_transforms(g[:, :7], g[:, 7:])
        centres, _ = hand.spheres(g[:, :7], g[:, 7:], transforms=T)
        reach.append(wrap_reach(hand, [box], torch.zeros(4, dtype=torch.long), T, centres[:, contact_sphere_index(hand)]))
    assert float(reach[1].mean()) > float(reach[0].mean()) + 0.003, reach
