"""Single-view depth of an object: cameras around it, MuJoCo depth images, back-projection.

Camera convention (MuJoCo's): a camera looks along its frame's -z axis, +x to the image's right,
+y up; its pose is ``[x y z qw qx qy qz]`` of that frame in the object frame. A W x H image with
vertical field of view ``fovy`` has square pixels of focal length ``f = (H / 2) / tan(fovy / 2)``
and its principal point at ``(W / 2, H / 2)``; the pixel in row ``i`` (from the top) and column
``j`` has its centre at ``u = j + 0.5, v = i + 0.5``, and a depth ``d`` (metres along the viewing
axis, as MuJoCo's renderer returns it) back-projects to the camera-frame point
``((u - cx) d / fx, -(v - cy) d / fy, -d)``.

Two renderers of the same camera model: `render_depth` (MuJoCo's renderer; needs an offscreen
OpenGL backend chosen before mujoco is imported, `datagen.gl.select_backend`, and
`datagen.objects.observations` renders in a worker process that starts with it) and
`raycast_depth` (trimesh's ray-triangle intersection of each pixel centre's ray: no GL, ~2x
slower). On the pixels both see they agree within 1e-4 of the camera distance (float32 rounding
typically), but for a pixel or two in a thousand whose centre lies on an occluding edge; their
silhouettes differ by at most a pixel or two (tests/objects/test_views.py; 8 processed objects, 4
views each: at most 2 of ~3000 pixels off by more than 1e-4 of the distance).
Shapes: V views, H x W pixels, n points.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["RENDERERS", "back_project", "intrinsics", "look_at_poses", "random_directions", "pixel_rays",
           "raycast_depth", "render", "render_depth"]

RENDERERS = ("mujoco", "raycast")  #: what `render` accepts


def intrinsics(width: int, height: int, fovy_deg: float) -> np.ndarray:
    """(4,) ``[fx, fy, cx, cy]`` pixels of a MuJoCo camera rendering ``width`` x ``height``."""
    f = (height / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    return np.array([f, f, width / 2.0, height / 2.0])


def random_directions(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) unit vectors, uniform on the sphere."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion [w x y z] (w >= 0) of a rotation matrix (3, 3)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    q = np.array([w, x, y, z])
    return -q if q[0] < 0 else q


def look_at_poses(directions: np.ndarray, distance: float) -> np.ndarray:
    """(V, 7) camera poses at ``distance`` from the origin along ``directions`` (V, 3), each
    looking at the origin with the image's up as close to +z as it can be (+y for a camera on
    the z axis)."""
    out = []
    for d in np.asarray(directions, np.float64):
        z = d / np.linalg.norm(d)  # the camera looks along -z, at the origin
        up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
        x = np.cross(up, z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        out.append(np.concatenate([distance * z, _matrix_to_quat(np.stack([x, y, z], axis=1))]))
    return np.array(out).reshape(-1, 7)


def _rotation(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(quat, np.float64) / np.linalg.norm(quat)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def back_project(depth: np.ndarray, pose: np.ndarray, intr: np.ndarray, max_depth: float) -> tuple:
    """Object-frame points of the pixels of ``depth`` (H, W) nearer than ``max_depth`` (the
    background lies at the far plane), seen by a camera at ``pose`` (7,) with intrinsics ``intr``
    ``[fx, fy, cx, cy]`` (module docstring). Returns ``(points (n, 3), pixels (n,))``: the points
    in row-major pixel order and their flat pixel indices ``i * W + j``."""
    depth = np.asarray(depth, np.float64)
    fx, fy, cx, cy = intr
    i, j = np.nonzero(depth < max_depth)
    d = depth[i, j]
    cam = np.stack([(j + 0.5 - cx) * d / fx, -(i + 0.5 - cy) * d / fy, -d], axis=1)
    pts = cam @ _rotation(pose[3:]).T + np.asarray(pose[:3], np.float64)
    return pts, i * depth.shape[1] + j


def render_depth(vertices: np.ndarray, faces: np.ndarray, poses: np.ndarray, width: int, height: int,
                 fovy_deg: float, far: float) -> np.ndarray:
    """(V, H, W) float32 depth images of the mesh (``vertices`` (N, 3), ``faces`` (F, 3), in the
    poses' units) from cameras at ``poses`` (V, 7); the background is at ``far`` (the far
    clipping plane). MuJoCo's renderer on a model of the mesh alone (reversed-z depth buffer,
    near plane at far / 1e4)."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.visual.global_.offwidth, spec.visual.global_.offheight = int(width), int(height)
    spec.stat.extent = float(far)  # the clipping planes are fractions of the extent
    spec.visual.map.znear, spec.visual.map.zfar = 1e-4, 1.0
    mesh = spec.add_mesh()
    mesh.name = "object"
    mesh.uservert = np.asarray(vertices, np.float64).ravel().tolist()
    mesh.userface = np.asarray(faces, np.int64).ravel().tolist()
    mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL  # rendering only: any closed or open surface
    geom = spec.worldbody.add_geom()
    geom.type, geom.meshname = mujoco.mjtGeom.mjGEOM_MESH, "object"
    for p in np.asarray(poses, np.float64):
        cam = spec.worldbody.add_camera()
        cam.pos, cam.quat, cam.fovy = p[:3].tolist(), p[3:].tolist(), float(fovy_deg)
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    out = np.empty((len(poses), int(height), int(width)), np.float32)
    renderer = mujoco.Renderer(model, int(height), int(width))
    try:
        renderer.enable_depth_rendering()
        for k in range(len(poses)):
            renderer.update_scene(data, camera=k)
            out[k] = renderer.render()
    finally:
        renderer.close()  # explicitly: its destructor raises at interpreter exit
    return out


def pixel_rays(width: int, height: int, fovy_deg: float) -> np.ndarray:
    """(H * W, 3) camera-frame directions through each pixel centre, row-major, with z = -1 (so a
    hit at ray parameter ``t`` has depth ``t``)."""
    fx, fy, cx, cy = intrinsics(width, height, fovy_deg)
    j, i = np.meshgrid(np.arange(width), np.arange(height))
    return np.stack([(j + 0.5 - cx) / fx, -(i + 0.5 - cy) / fy, -np.ones((height, width))], -1).reshape(-1, 3)


def raycast_depth(vertices: np.ndarray, faces: np.ndarray, poses: np.ndarray, width: int, height: int,
                  fovy_deg: float, far: float) -> np.ndarray:
    """`render_depth` without OpenGL: (V, H, W) float32 depth along each camera's viewing axis of
    the first triangle each pixel centre's ray hits (trimesh's ray-triangle intersector), ``far``
    where it hits none or only beyond ``far``."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces, np.int64), process=False)
    caster = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
    rays = pixel_rays(width, height, fovy_deg)
    out = np.full((len(poses), height * width), far, np.float32)
    lo, hi = mesh.bounds
    for k, p in enumerate(np.asarray(poses, np.float64)):
        R = _rotation(p[3:])
        dirs = rays @ R.T
        with np.errstate(divide="ignore", invalid="ignore"):  # the slab test of the bounding box first
            t1, t2 = (lo - p[:3]) / dirs, (hi - p[:3]) / dirs
            near = np.nanmax(np.minimum(t1, t2), axis=1)
            far_t = np.nanmin(np.maximum(t1, t2), axis=1)
        cand = np.flatnonzero(far_t >= np.maximum(near, 0.0))
        hit, ray, _ = caster.intersects_location(np.broadcast_to(p[:3], (len(cand), 3)), dirs[cand],
                                                 multiple_hits=False)
        depth = -(hit - p[:3]) @ R[:, 2]  # along the viewing axis (-z of the camera)
        keep = depth < far
        out[k, cand[ray[keep]]] = depth[keep]
    return out.reshape(len(poses), height, width)


def render(renderer: str, *args) -> np.ndarray:
    """`render_depth` (``"mujoco"``) or `raycast_depth` (``"raycast"``) of the same arguments."""
    if renderer not in RENDERERS:
        raise ValueError(f"renderer must be one of {RENDERERS}, got {renderer!r}")
    return (render_depth if renderer == "mujoco" else raycast_depth)(*args)
