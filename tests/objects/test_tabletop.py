"""Stable poses on a table against hand-computed cases: a box rests on its six faces (the large
ones most often, the support plane at the half extent), a cylinder on its side (its facets one
pose) and its two ends; the pose's transform puts the mesh on z = 0 with the centre of mass above
its support, and the plane in the object frame gives each vertex its height above the table."""

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull

from datagen.errors import ConfigError
from datagen.objects.tabletop import SceneConfig, stable_poses


def _poses(mesh, count=16, com=None):
    return stable_poses(mesh.vertices, mesh.faces, mesh.center_mass if com is None else com, count)


def test_a_box_rests_on_its_six_faces_the_largest_most_often():
    ext = np.array([0.2, 0.4, 0.8])
    poses = _poses(trimesh.creation.box(ext))
    assert len(poses) == 6
    normals = np.array([p.normal for p in poses])
    axes = np.abs(normals).argmax(1)
    # each face once: the table's up direction along +-x, +-y, +-z of the object
    assert sorted(zip(axes, np.sign(normals[np.arange(6), axes]))) == sorted(
        (a, s) for a in range(3) for s in (-1.0, 1.0))
    assert np.allclose(np.abs(normals).max(1), 1.0, atol=1e-9)
    # most probable first: lying on the 0.4 x 0.8 faces (up = +-x), then +-y, then on the small ends
    assert list(axes) == [0, 0, 1, 1, 2, 2]
    probs = [p.probability for p in poses]
    assert probs == sorted(probs, reverse=True) and sum(probs) == pytest.approx(1.0, abs=1e-6)
    for p in poses:  # the support plane lies at the half extent below the centre
        k = np.abs(p.normal).argmax()
        assert p.plane(1.0)[3] == pytest.approx(ext[k] / 2, abs=1e-9)
        # quasi-static: the face's solid angle from the centre over 4 pi (a rectangle a x b at d)
        a, b = np.delete(ext, k)
        d = ext[k] / 2
        assert p.probability == pytest.approx(np.arcsin(a * b / np.sqrt((a * a + 4 * d * d) * (b * b + 4 * d * d)))
                                              / np.pi, abs=1e-6)


def test_a_cylinder_rests_on_its_side_then_its_ends():
    r, h = 0.1, 0.5
    poses = _poses(trimesh.creation.cylinder(radius=r, height=h, sections=64))
    assert len(poses) == 3  # the 64 side facets are one pose
    side, ends = poses[0], poses[1:]
    assert abs(side.normal[2]) < 1e-6 and side.plane(1.0)[3] == pytest.approx(r * np.cos(np.pi / 64), abs=1e-6)
    assert side.probability > 0.8
    assert sorted(np.sign(p.normal[2]) for p in ends) == [-1.0, 1.0]
    assert all(p.plane(1.0)[3] == pytest.approx(h / 2, abs=1e-9) for p in ends)


def test_the_transform_puts_the_mesh_on_the_table_and_the_plane_gives_heights():
    mesh = trimesh.creation.capsule(height=0.3, radius=0.08)
    mesh.apply_transform(trimesh.transformations.random_rotation_matrix(np.random.default_rng(3).random(3)))
    mesh.apply_translation([0.01, -0.02, 0.03])
    for p in _poses(mesh, 4):
        for s in (1.0, 0.07):
            v = mesh.vertices * s
            table = v @ p.transform[:3, :3].T + p.transform[:3, 3] * s  # object -> table frame
            assert table[:, 2].min() == pytest.approx(0.0, abs=1e-9)
            n, d = p.plane(s)[:3], p.plane(s)[3]
            assert np.allclose(v @ n + d, table[:, 2], atol=1e-9)
            pose = p.pose7(s)  # the same transform as position + unit quaternion
            R = trimesh.transformations.quaternion_matrix(pose[3:])[:3, :3]
            assert np.allclose(R, p.transform[:3, :3], atol=1e-9) and np.allclose(pose[:3], p.transform[:3, 3] * s)
        # its centre of mass rests above the support polygon (a stable pose)
        com = mesh.center_mass @ p.transform[:3, :3].T + p.transform[:3, 3]
        ground = mesh.vertices @ p.transform[:3, :3].T + p.transform[:3, 3]
        support = ground[ground[:, 2] < 1e-6][:, :2]
        hull = ConvexHull(support)
        assert np.all(hull.equations[:, :2] @ com[:2] + hull.equations[:, 2] <= 1e-9)


def test_the_centre_of_mass_decides_the_pose():
    box = trimesh.creation.box((0.2, 0.2, 0.2))  # a cube: every face alike, unless the mass is off-centre
    low = _poses(box, 1, com=np.array([0.0, 0.0, -0.09]))[0]
    assert np.allclose(low.normal, [0, 0, 1], atol=1e-9)  # weighted at its -z face: rests on it
    # the quasi-static probability is the face's solid angle seen from the centre of mass over 4 pi:
    # a 0.2 x 0.2 square 0.01 below it, 4 asin(a b / sqrt((a^2 + 4 d^2)(b^2 + 4 d^2))) / (4 pi)
    a, d = 0.2, 0.01
    assert low.probability == pytest.approx(np.arcsin(a * a / (a * a + 4 * d * d)) / np.pi, abs=1e-6)


def test_scene_config_checks_its_fields():
    assert SceneConfig().kind == "floating" and not SceneConfig().tabletop
    assert SceneConfig.from_dict({"kind": "tabletop", "stable_poses": 3}).tabletop
    with pytest.raises(ConfigError, match="scene.kind"):
        SceneConfig(kind="table")
    with pytest.raises(ConfigError, match="stable_poses"):
        SceneConfig(kind="tabletop", stable_poses=0)


def test_footprint_of_a_box_on_a_tilted_table_is_its_hand_measured_extent():
    """A 6 x 4 x 2 cm box on its largest face, the object frame turned at random: the footprint
    is 2 cm high, 4 cm wide across the box's y edge, 6 cm long, centred under the box."""
    from scipy.spatial.transform import Rotation

    from datagen.objects.tabletop import footprint

    box = trimesh.creation.box([0.06, 0.04, 0.02])
    R = Rotation.random(random_state=3).as_matrix()
    verts = (box.vertices + [0.01, -0.02, 0.03]) @ R.T  # the box, moved and turned in the object frame
    up = R @ [0, 0, 1.0]
    plane = np.array([*up, -0.02])  # its bottom face (z = 0.02 before turning) is the table
    fp = footprint(verts, plane)
    assert fp.height == pytest.approx(0.02, abs=1e-9)
    assert fp.width == pytest.approx(0.04, abs=1e-9) and fp.length == pytest.approx(0.06, abs=1e-9)
    assert abs(fp.axis @ (R @ [0, 1.0, 0])) == pytest.approx(1.0, abs=1e-9)
    assert fp.axis @ up == pytest.approx(0.0, abs=1e-12)
    assert fp.centre == pytest.approx(R @ [0.01, -0.02, 0.02], abs=1e-9)  # under the box's centre, on the table
    assert fp.centre @ up + plane[3] == pytest.approx(0.0, abs=1e-12)
