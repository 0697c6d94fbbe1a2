"""Static metrics against analytic geometry: penetration depth, distances, contact normals."""

import numpy as np
import pytest

from datagen.eval import EvalConfig, Evaluator
from datagen.eval.metrics import self_penetration, set_static_pose, static_metrics

from .grasps import box_pieces

pytestmark = pytest.mark.mujoco

H = 0.04  # m, half side of a cube object


def _capsule_reach(scene, data):
    """Per hand capsule geom: highest z of the capsule surface (analytic: endpoints + radius)."""
    m = scene.model
    out = {}
    for g in scene.hand_geoms:
        if m.geom_type[g] != 3:  # mjGEOM_CAPSULE
            continue
        r, half = m.geom_size[g, 0], m.geom_size[g, 1]
        axis = data.geom_xmat[g].reshape(3, 3)[:, 2]
        ends = data.geom_xpos[g] + np.outer([-half, half], axis)
        out[int(g)] = (ends[:, 2].max() + r, ends[np.argmax(ends[:, 2])])
    return out


def _open_hand_reach(shadow, scene, data):
    """Open hand at the identity root: (joints, capsule reach, highest tip z, that tip point)."""
    open_joints = np.zeros(shadow.num_joints)
    set_static_pose(scene, data, np.concatenate([[0, 0, 0, 1, 0, 0, 0], open_joints]))
    reach = _capsule_reach(scene, data)
    z_top, tip = reach[max(reach, key=lambda g: reach[g][0])]
    return open_joints, reach, z_top, tip


@pytest.fixture(scope="module")
def cube_scene(shadow, box_dir):
    ev = Evaluator(shadow, EvalConfig())
    pieces = box_pieces((H, H, H), box_dir, name="cube")
    scene, datas = ev.scene(pieces)
    return scene, datas[-1]


@pytest.mark.parametrize("depth", [0.0015, 0.003])
def test_penetration_matches_analytic_depth(shadow, cube_scene, depth):
    scene, data = cube_scene
    # open hand, fingers along +z: raise the hand so that its highest capsule's tip enters the
    # cube's bottom face (z = -H) by `depth`, under the face's centre
    open_joints, reach, z_top, tip = _open_hand_reach(shadow, scene, data)
    second = sorted(v[0] for v in reach.values())[-2]
    assert z_top - second > depth + 1e-4  # only that fingertip overlaps: the analytic depth is unique
    shift = np.array([-tip[0], -tip[1], -H + depth - z_top])
    row = np.concatenate([shift, [1, 0, 0, 0], open_joints])
    met = static_metrics(scene, data, row, touch_distance=0.002, contact_distance=0.005)
    assert abs(met.penetration - depth) < 1e-6
    assert abs(met.min_distance + depth) < 1e-6
    # the contact of that fingertip: on the bottom face, normal pointing into the cube (+z)
    k = np.argmin(np.abs(met.contact_points[:, 2] + H) + np.linalg.norm(met.contact_points[:, :2], axis=1))
    assert abs(met.contact_points[k, 2] + H) < 1e-6
    assert np.allclose(met.contact_normals[k], [0, 0, 1], atol=1e-6)
    assert np.allclose(np.linalg.norm(met.contact_normals, axis=1), 1.0)


def test_separated_fingertip_distance_and_normal(shadow, cube_scene):
    scene, data = cube_scene
    open_joints, _, z_top, tip = _open_hand_reach(shadow, scene, data)
    gap = 0.0035
    row = np.concatenate([[-tip[0], -tip[1], -H - gap - z_top], [1, 0, 0, 0], open_joints])
    met = static_metrics(scene, data, row, touch_distance=0.002, contact_distance=0.005)
    assert met.penetration == 0.0 and abs(met.min_distance - gap) < 1e-6
    assert met.touching_links == 0  # 3.5 mm is beyond the 2 mm touch distance
    assert len(met.contact_points) >= 1  # but within the 5 mm contact distance of the epsilon
    k = np.argmin(np.linalg.norm(met.contact_points[:, :2], axis=1))
    assert np.allclose(met.contact_normals[k], [0, 0, 1], atol=1e-6)
    mf = shadow.fingertip_names.index("mf")
    assert abs(met.finger_distance[mf] - gap) < 1e-6  # the middle finger is the longest


def test_self_penetration_zero_open_positive_when_crossed(shadow, cube_scene):
    scene, data = cube_scene
    q = np.zeros(shadow.num_joints)
    set_static_pose(scene, data, np.concatenate([[1, 1, 1, 1, 0, 0, 0], q]))
    assert self_penetration(scene, data) == 0.0
    # index and middle finger spread towards each other (FFJ3 / MFJ3 about the palm normal)
    names = shadow.joint_names
    q[names.index("robot0:FFJ3")] = -0.349
    q[names.index("robot0:MFJ3")] = 0.349
    set_static_pose(scene, data, np.concatenate([[1, 1, 1, 1, 0, 0, 0], q]))
    assert self_penetration(scene, data) > 0.003
