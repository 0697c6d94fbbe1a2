"""Collision geometry of a hand's links, as MuJoCo collides it, in link (body) frames.

Every collision geom becomes a convex `Shape`: spheres, capsules, cylinders and boxes exactly;
meshes as their convex hull (MuJoCo collides meshes through their hulls); ellipsoids as an
inscribed polytope. A shape answers two questions, vectorized over points (..., 3) in metres:
``depth`` (distance from an interior point to the shape's surface; <= 0 outside) and surface
samples with outward normals.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh

from datagen.rotation import quat_to_matrix_np

__all__ = ["points_outward", "Shape", "link_shapes", "sample_link_surface", "union_depth", "collision_links"]

_SPHERE, _CAPSULE, _CYLINDER, _BOX, _POLY = "sphere", "capsule", "cylinder", "box", "polytope"


@dataclass(frozen=True)
class Shape:
    """One convex collision shape in its link's frame.

    kind: sphere | capsule | cylinder | box | polytope. size: MuJoCo geom size (m).
    pos (3,), rot (3, 3): geom frame in the link frame. planes (P, 4): polytope as n.x <= b rows
    [n, b] in the geom frame (polytope only). mesh: a trimesh of the surface in the link frame.
    """

    kind: str
    size: np.ndarray
    pos: np.ndarray
    rot: np.ndarray
    mesh: trimesh.Trimesh
    planes: np.ndarray | None = None
    geom: int = -1

    def depth(self, points: np.ndarray) -> np.ndarray:
        """(...,) distance from ``points`` (..., 3, link frame, m) to the surface, positive inside."""
        p = (np.asarray(points) - self.pos) @ self.rot  # into the geom frame
        s = self.size
        if self.kind == _SPHERE:
            return s[0] - np.linalg.norm(p, axis=-1)
        if self.kind == _CAPSULE:
            z = np.clip(p[..., 2], -s[1], s[1])
            return s[0] - np.linalg.norm(p - np.stack([0 * z, 0 * z, z], -1), axis=-1)
        if self.kind == _CYLINDER:
            return np.minimum(s[0] - np.linalg.norm(p[..., :2], axis=-1), s[1] - np.abs(p[..., 2]))
        if self.kind == _BOX:
            return np.min(s[:3] - np.abs(p), axis=-1)
        planes = self.planes
        return np.min(planes[:, 3] - p @ planes[:, :3].T, axis=-1)


def _hull_planes(hull: trimesh.Trimesh) -> np.ndarray:
    normals = hull.face_normals
    offsets = np.einsum("ij,ij->i", normals, hull.triangles[:, 0])
    return np.concatenate([normals, offsets[:, None]], axis=1)


def collision_links(model: mujoco.MjModel) -> list[int]:
    """Body ids (in model order) that carry at least one collision geom."""
    ids = []
    for b in range(1, model.nbody):
        if any(_is_collision(model, g) for g in range(model.ngeom) if model.geom_bodyid[g] == b):
            ids.append(b)
    return ids


def _is_collision(model: mujoco.MjModel, g: int) -> bool:
    return bool(model.geom_contype[g] or model.geom_conaffinity[g])


def link_shapes(model: mujoco.MjModel, body: int) -> list[Shape]:
    """Convex collision shapes of body ``body`` (collision geom = contype or conaffinity non-zero)."""
    shapes: list[Shape] = []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body or not _is_collision(model, g):
            continue
        gtype, size = mujoco.mjtGeom(int(model.geom_type[g])), model.geom_size[g].copy()
        pos, rot = model.geom_pos[g].copy(), quat_to_matrix_np(model.geom_quat[g])
        planes = None
        if gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
            kind, local = _SPHERE, trimesh.creation.icosphere(subdivisions=3, radius=size[0])
        elif gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
            kind, local = _CAPSULE, trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[32, 32])
        elif gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
            kind, local = _CYLINDER, trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=48)
        elif gtype == mujoco.mjtGeom.mjGEOM_BOX:
            kind, local = _BOX, trimesh.creation.box(extents=2 * size)
        elif gtype in (mujoco.mjtGeom.mjGEOM_MESH, mujoco.mjtGeom.mjGEOM_ELLIPSOID):
            if gtype == mujoco.mjtGeom.mjGEOM_MESH:
                mid = model.geom_dataid[g]
                adr, n = model.mesh_vertadr[mid], model.mesh_vertnum[mid]
                verts = model.mesh_vert[adr:adr + n].astype(np.float64)
            else:
                verts = trimesh.creation.icosphere(subdivisions=3).vertices * size
            local = trimesh.convex.convex_hull(verts)
            kind, planes = _POLY, _hull_planes(local)
        else:
            continue  # planes, height fields, SDFs are not hand link geometry
        mesh = local.copy()
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = rot, pos
        mesh.apply_transform(T)
        shapes.append(Shape(kind=kind, size=size, pos=pos, rot=rot, mesh=mesh, planes=planes, geom=g))
    return shapes


def points_outward(shapes: list[Shape], point: np.ndarray, normal: np.ndarray, eps: float = 0.001) -> bool:
    """Whether ``normal`` points out of the union of ``shapes`` at the surface ``point``: a step of
    ``eps`` against it is inside, one along it is not (robust at the edges of boxes and hulls,
    where the surface has no gradient)."""
    inside, outside = union_depth(shapes, np.stack([point - eps * normal, point + eps * normal]))
    return bool(inside > 0 > outside)


def union_depth(shapes: list[Shape], points: np.ndarray) -> np.ndarray:
    """(...,) a lower bound of the depth of ``points`` inside the union of ``shapes``: the ball of
    that radius around each point lies inside one shape."""
    return np.max(np.stack([s.depth(points) for s in shapes], axis=0), axis=0)


def sample_link_surface(shapes: list[Shape], count: int, rng: np.random.Generator,
                        exterior_only: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted samples on the link's collision surface: points (N, 3) and outward normals
    (N, 3), link frame. ``exterior_only`` drops points buried inside another shape of the link."""
    areas = np.array([s.mesh.area for s in shapes])
    counts = np.maximum(1, np.round(count * areas / areas.sum()).astype(int))
    pts, nrm = [], []
    for i, (shape, n) in enumerate(zip(shapes, counts)):
        p, face = trimesh.sample.sample_surface(shape.mesh, int(n), seed=int(rng.integers(2**31)))
        normal = shape.mesh.face_normals[face]
        if exterior_only and len(shapes) > 1:
            others = [s for j, s in enumerate(shapes) if j != i]
            keep = union_depth(others, p) <= 1e-6
            p, normal = p[keep], normal[keep]
        pts.append(p)
        nrm.append(normal)
    return np.concatenate(pts), np.concatenate(nrm)
