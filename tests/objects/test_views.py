"""Camera views (datagen/objects/views.py) against hand-computed cases: the back-projection of
a known depth image, a box's depth seen head-on (an analytic plane), and MuJoCo's renderer
against trimesh's ray casting of the same cameras."""

import math

import numpy as np
import pytest
import trimesh

from datagen.objects.views import (back_project, intrinsics, look_at_poses, random_directions, raycast_depth,
                                   render_depth)


def _gl() -> str:
    """The offscreen backend MuJoCo renders with here ('' if none), probed in a subprocess: this
    process's environment is left as it is (mujoco may be imported already, with no backend)."""
    import os

    from datagen.gl import BACKENDS, probe

    want = os.environ.get("MUJOCO_GL", "").lower()
    return next((b for b in ([want] if want in BACKENDS else list(BACKENDS)) if not probe(b)), "")


GL = _gl()
needs_gl = pytest.mark.skipif(not GL, reason="MuJoCo's depth renderer needs an offscreen OpenGL backend "
                                             "(egl: apt-get install libegl1, or osmesa: libosmesa6)")


def mujoco_depth(*args):
    """`render_depth` in a fresh worker interpreter started with ``MUJOCO_GL`` set (as
    `datagen.objects.observations` renders: never in a process whose mujoco is already loaded)."""
    import os

    from datagen.objects.isolate import call_isolated

    before = os.environ.get("MUJOCO_GL")
    os.environ["MUJOCO_GL"] = GL
    try:
        return call_isolated(render_depth, args, 120.0, what="rendering", fresh=True)
    finally:
        if before is None:
            del os.environ["MUJOCO_GL"]
        else:
            os.environ["MUJOCO_GL"] = before


def _rot(pose):
    from scipy.spatial.transform import Rotation

    w, x, y, z = pose[3:]
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def test_intrinsics_hand_case():
    # fovy 90 deg: the half height is the focal length
    np.testing.assert_allclose(intrinsics(8, 4, 90.0), [2.0, 2.0, 4.0, 2.0])


def test_back_project_hand_case():
    # identity camera at the origin, f = 2, 4 x 2 image; pixel (row 0, col 3) has centre (3.5, 0.5):
    # x = (3.5 - 2) * d / 2, y = -(0.5 - 1) * d / 2, z = -d
    depth = np.full((2, 4), 9.0)
    depth[0, 3] = 2.0
    depth[1, 0] = 4.0
    pts, px = back_project(depth, np.array([0, 0, 0, 1.0, 0, 0, 0]), np.array([2.0, 2.0, 2.0, 1.0]), 5.0)
    np.testing.assert_array_equal(px, [3, 4])
    np.testing.assert_allclose(pts, [[1.5, 0.5, -2.0], [-3.0, -1.0, -4.0]])
    # a camera at (1, 2, 3) turned 180 deg about y: camera -z is world +z, camera x is world -x
    pts2, _ = back_project(depth, np.array([1.0, 2.0, 3.0, 0.0, 0.0, 1.0, 0.0]), np.array([2.0, 2.0, 2.0, 1.0]), 5.0)
    np.testing.assert_allclose(pts2, [[1 - 1.5, 2 + 0.5, 3 + 2.0], [1 + 3.0, 2 - 1.0, 3 + 4.0]])


def test_look_at_poses_look_at_the_origin_upright():
    dirs = np.vstack([random_directions(16, np.random.default_rng(0)), [[0, 0, 1.0]], [[0, 0, -1.0]]])
    poses = look_at_poses(dirs, 0.4)
    for d, p in zip(dirs, poses):
        R = _rot(p)
        np.testing.assert_allclose(p[:3], 0.4 * d, atol=1e-12)
        np.testing.assert_allclose(R @ [0, 0, -1.0], -d, atol=1e-9)  # looking at the origin
        assert abs(np.linalg.det(R) - 1) < 1e-9
        if abs(d[2]) < 0.99:
            assert abs((R @ [1.0, 0, 0])[2]) < 1e-9 and (R @ [0, 1.0, 0])[2] > 0  # level, up is up


def _box_head_on(render):
    # a 1 x 0.7 x 0.5 box seen from +x at 3: depth 2.5 on the face x = 0.5, which spans
    # y in [-0.35, 0.35], z in [-0.25, 0.25]
    box = trimesh.creation.box((1.0, 0.7, 0.5))
    pose = look_at_poses(np.array([[1.0, 0, 0]]), 3.0)
    W, H, fov = 64, 48, 30.0
    depth = render(box.vertices, box.faces, pose, W, H, fov, 10.0)[0]
    pts, _ = back_project(depth, pose[0], intrinsics(W, H, fov), 9.99)
    hit = depth < 9.99
    np.testing.assert_allclose(depth[hit], 2.5, atol=1e-5)
    np.testing.assert_allclose(pts[:, 0], 0.5, atol=1e-5)
    assert np.all(np.abs(pts[:, 1]) <= 0.35 + 1e-6) and np.all(np.abs(pts[:, 2]) <= 0.25 + 1e-6)
    # the face's image: f = 24 / tan(15 deg); it covers |u - 32| < 0.35 f / 2.5, |v - 24| < 0.25 f / 2.5
    f = 24 / math.tan(math.radians(15))
    u, v = np.arange(W) + 0.5, np.arange(H) + 0.5
    want = (np.abs(v - 24)[:, None] < 0.25 * f / 2.5) & (np.abs(u - 32)[None, :] < 0.35 * f / 2.5)
    np.testing.assert_array_equal(hit, want)


def test_raycast_depth_of_a_box_head_on():
    _box_head_on(raycast_depth)


@needs_gl
def test_mujoco_depth_of_a_box_head_on():
    _box_head_on(mujoco_depth)


@needs_gl
def test_mujoco_and_raycast_agree_on_a_mesh_from_random_cameras():
    mesh = trimesh.creation.annulus(r_min=0.2, r_max=0.5, height=0.3, sections=24)  # not convex: occlusion
    poses = look_at_poses(random_directions(4, np.random.default_rng(1)), 2.0)
    a = mujoco_depth(mesh.vertices, mesh.faces, poses, 80, 60, 45.0, 6.0)
    b = raycast_depth(mesh.vertices, mesh.faces, poses, 80, 60, 45.0, 6.0)
    seen_a, seen_b = a < 0.999 * 6.0, b < 6.0
    assert seen_a.sum() > 4 * 300
    # pixel centres on a silhouette edge may fall either side: at most a few per view differ
    assert (seen_a != seen_b).sum() <= 0.01 * seen_a.sum()
    both = seen_a & seen_b
    # MuJoCo's depth buffer rounds: 1e-4 of the 2 m distance at worst, float32 rounding typically;
    # a pixel centre on an occluding edge may see the near or the far surface
    diff = np.abs(a[both] - b[both])
    assert (diff > 1e-4).sum() <= 0.002 * both.sum() and np.median(diff) < 1e-6
