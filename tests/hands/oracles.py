"""Independent references for the hand tests.

Surface samples are drawn here from MuJoCo's compiled geom data with textbook area-weighted
samplers (mesh geoms through scipy's convex hull, as MuJoCo collides meshes by their hulls), and
distances come from MuJoCo's own ``mj_geomDistance`` with a tiny probe sphere; neither shares
code with datagen.hands' fitting (which uses trimesh tessellations and analytic depths).
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

PROBE_RADIUS = 1e-6


def _random_unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _sample_triangles(tri, n, rng):
    a = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2
    k = rng.choice(len(tri), size=n, p=a / a.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[k]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def sample_geom_surface(model: mujoco.MjModel, g: int, n: int, rng) -> np.ndarray:
    """(n, 3) points on geom g's collision surface, in its body frame."""
    t, s = int(model.geom_type[g]), model.geom_size[g]
    G = mujoco.mjtGeom
    if t == G.mjGEOM_SPHERE:
        p = s[0] * _random_unit(rng, n)
    elif t == G.mjGEOM_CAPSULE:
        r, h = s[0], s[1]
        side = rng.random(n) < (4 * np.pi * r * h) / (4 * np.pi * r * h + 4 * np.pi * r * r)
        ang = rng.random(n) * 2 * np.pi
        p = np.stack([r * np.cos(ang), r * np.sin(ang), rng.uniform(-h, h, n)], 1)
        cap = r * _random_unit(rng, n)
        cap[:, 2] += np.sign(cap[:, 2]) * h
        p = np.where(side[:, None], p, cap)
    elif t == G.mjGEOM_CYLINDER:
        r, h = s[0], s[1]
        side = rng.random(n) < (2 * np.pi * r * 2 * h) / (2 * np.pi * r * 2 * h + 2 * np.pi * r * r)
        ang = rng.random(n) * 2 * np.pi
        p = np.stack([r * np.cos(ang), r * np.sin(ang), rng.uniform(-h, h, n)], 1)
        rad = r * np.sqrt(rng.random(n))
        cap = np.stack([rad * np.cos(ang), rad * np.sin(ang), np.where(rng.random(n) < 0.5, -h, h)], 1)
        p = np.where(side[:, None], p, cap)
    elif t == G.mjGEOM_BOX:
        areas = np.array([s[1] * s[2], s[0] * s[2], s[0] * s[1]] * 2)
        face = rng.choice(6, size=n, p=areas / areas.sum())
        p = rng.uniform(-1, 1, (n, 3)) * s[:3]
        axis = face % 3
        p[np.arange(n), axis] = np.where(face < 3, 1, -1) * s[axis]
    elif t == G.mjGEOM_MESH:
        mid = model.geom_dataid[g]
        v = model.mesh_vert[model.mesh_vertadr[mid]:model.mesh_vertadr[mid] + model.mesh_vertnum[mid]]
        hull = ConvexHull(v.astype(np.float64))
        p = _sample_triangles(hull.points[hull.simplices], n, rng)
    else:
        raise NotImplementedError(f"geom type {t}")
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, model.geom_quat[g])
    return p @ R.reshape(3, 3).T + model.geom_pos[g]


def collision_geoms(model: mujoco.MjModel, body: int) -> list[int]:
    return [g for g in range(model.ngeom)
            if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])]


class DistanceProbe:
    """Signed distance (m) from world points to geoms of a hand MJCF, by MuJoCo's mj_geomDistance."""

    def __init__(self, mjcf_path: str, qpos: np.ndarray | None = None) -> None:
        spec = mujoco.MjSpec.from_file(str(mjcf_path))
        body = spec.worldbody.add_body(name="__probe__", mocap=True)
        body.add_geom(name="__probe__", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[PROBE_RADIUS, 0, 0],
                      contype=0, conaffinity=0)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        if qpos is not None:
            self.data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, self.data)
        self.probe = self.model.geom("__probe__").id
        self._fromto = np.zeros(6)

    def body_frame(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        return self.data.xmat[body].reshape(3, 3).copy(), self.data.xpos[body].copy()

    def distance(self, points: np.ndarray, geoms: list[int], distmax: float = 1.0) -> np.ndarray:
        """(N,) min over ``geoms`` of the signed distance of each world point (negative inside)."""
        out = np.full(len(points), np.inf)
        for i, p in enumerate(points):
            self.data.geom_xpos[self.probe] = p
            for g in geoms:
                d = mujoco.mj_geomDistance(self.model, self.data, self.probe, g, distmax, self._fromto)
                out[i] = min(out[i], d + PROBE_RADIUS)
        return out
