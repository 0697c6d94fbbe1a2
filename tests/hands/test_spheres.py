"""Collision spheres and fingertip contact points against the collision geometry MuJoCo uses."""

import numpy as np
import pytest
import torch

from .conftest import get_hand, hand_params
from .oracles import DistanceProbe, collision_geoms, sample_geom_surface

COVERAGE_MIN = 0.95  # of surface samples, whole hand
LINK_COVERAGE_MIN = 0.80  # every link (the LEAP palm, ten thin boxes, is the weakest at ~0.85)
OVERSHOOT_MAX = 0.003  # m
CONTACT_TOL = 0.002  # m


def _hand_and_probe(name):
    hand = get_hand(name)
    probe = DistanceProbe(hand.mjcf_path, qpos=hand.joints_to_qpos(hand.open_pose))
    return hand, probe


@pytest.mark.mujoco
@pytest.mark.parametrize("name", hand_params())
def test_spheres_cover_collision_surface(name):
    hand, probe = _hand_and_probe(name)
    rng = np.random.default_rng(0)
    model = probe.model
    centres = hand.sphere_centres_local.numpy()
    radii = hand.sphere_radii.numpy()
    links = hand.sphere_link_index.numpy()
    covered_total = sampled_total = 0
    for li, link in enumerate(hand.link_names):
        body = model.body(link).id
        geoms = collision_geoms(model, body)
        if not geoms:
            continue
        R, t = probe.body_frame(body)
        pts = []
        for g in geoms:
            p = sample_geom_surface(model, g, 300, rng)
            others = [o for o in geoms if o != g]
            if others:  # keep the exterior of the link's union of geoms only
                p = p[probe.distance(p @ R.T + t, others) > -1e-6]
            pts.append(p)
        pts = np.concatenate(pts)
        mine = links == li
        assert mine.any(), f"{name}: link {link} has collision geometry but no spheres"
        d = np.linalg.norm(pts[:, None, :] - centres[None, mine], axis=-1)
        covered = (d <= radii[None, mine] + 1e-9).any(axis=1)
        assert covered.mean() >= LINK_COVERAGE_MIN, f"{name}: link {link} coverage {covered.mean():.3f}"
        covered_total += covered.sum()
        sampled_total += len(pts)
    assert covered_total / sampled_total >= COVERAGE_MIN, f"{name}: coverage {covered_total / sampled_total:.3f}"


@pytest.mark.mujoco
@pytest.mark.parametrize("name", hand_params())
def test_spheres_overshoot_at_most_3mm(name):
    hand, probe = _hand_and_probe(name)
    rng = np.random.default_rng(1)
    model = probe.model
    root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=hand.dtype)
    world_c, radii = hand.spheres(root, hand.open_pose)
    world_c, radii = world_c.numpy(), radii.numpy()
    links = hand.sphere_link_index.numpy()
    dirs = rng.normal(size=(24, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    worst = 0.0
    for s in range(len(radii)):
        geoms = collision_geoms(model, model.body(hand.link_names[links[s]]).id)
        d = probe.distance(world_c[s] + radii[s] * dirs, geoms)
        worst = max(worst, float(d.max()))
    assert worst <= OVERSHOOT_MAX, f"{name}: spheres reach {worst * 1e3:.2f} mm beyond the geometry"


@pytest.mark.mujoco
@pytest.mark.parametrize("name", hand_params())
def test_contact_points_on_fingertip_pads(name):
    hand, probe = _hand_and_probe(name)
    model = probe.model
    root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=hand.dtype)
    tips = hand.fingertip_points(root, hand.open_pose).numpy()
    normals = hand.fingertip_normals(root, hand.open_pose).numpy()
    assert len(hand.fingertip_names) >= 3
    for f, name_f in enumerate(hand.fingertip_names):
        link = hand.link_names[hand.fingertip_link_index[f]]
        geoms = collision_geoms(model, model.body(link).id)
        d = probe.distance(tips[f:f + 1], geoms)[0]
        assert abs(d) <= CONTACT_TOL, f"{name}/{name_f}: contact point {d * 1e3:.2f} mm from the surface"
        # the normal points out of the geometry: a step outwards moves away from the surface
        out = probe.distance(tips[f:f + 1] + 0.003 * normals[f:f + 1], geoms)[0]
        assert out > d + 0.002, f"{name}/{name_f}: pad normal does not point out of the fingertip"


@pytest.mark.parametrize("name", hand_params())
def test_palm_frame_and_pads_face_the_grasp(name):
    """Approach and thumb axes are orthonormal; the non-thumb pads face along the approach axis."""
    hand = get_hand(name)
    root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=hand.dtype)
    palm = hand.palm_frame(root, hand.open_pose)
    assert torch.allclose(palm.approach.norm(), torch.tensor(1.0, dtype=hand.dtype), atol=1e-6)
    assert torch.allclose(palm.thumb.norm(), torch.tensor(1.0, dtype=hand.dtype), atol=1e-6)
    assert abs(float(palm.approach @ palm.thumb)) < 1e-3
    normals = hand.fingertip_normals(root, hand.open_pose)
    facing = normals @ palm.approach
    assert (facing > 0).sum() >= len(hand.fingertip_names) - 1


@pytest.mark.parametrize("name", hand_params())
def test_self_collision_pairs(name):
    """No adjacent links in the pairs and nothing overlapping in the open pose."""
    hand = get_hand(name)
    model = hand.mj_model
    for a, b in hand.self_collision_link_pairs:
        ia, ib = model.body(a).id, model.body(b).id
        assert model.body_parentid[ia] != ib and model.body_parentid[ib] != ia
    root = torch.tensor([0, 0, 0, 1, 0, 0, 0], dtype=hand.dtype)
    assert hand.self_penetration(root, hand.open_pose).max() == 0
    assert len(hand.self_collision_pairs) > 0
