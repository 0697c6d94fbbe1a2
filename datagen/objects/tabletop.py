"""Scenes: an object floating in space, or resting on a table in one of its stable poses.

``floating`` (the default) is the object alone, gravity off (the six-direction hold test).
``tabletop`` puts the object on a horizontal plane, the table, in its stable poses: the rest
poses of its convex hull on a plane under its centre of mass (`trimesh.poses.compute_stable_poses`
on the processed surface, the most probable first), ``stable_poses`` of them per object. A
stable pose is a rigid transform of the object into the *table frame* (table surface z = 0,
+z up). Synthesis and the rows keep working in the object's own frame, where the table is the
*support plane* ``n . x + d = 0``: ``n`` (3,) the table's up direction in the object frame and
``d`` (m) its offset, so ``n . x + d`` is a point's height above the table (m).

Both scale with the object: at ``s`` metres per normalized unit the pose's translation and ``d``
are ``s`` times their normalized values, the rotation and ``n`` unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datagen.config import Config
from datagen.errors import ConfigError

__all__ = ["SCENES", "Footprint", "SceneConfig", "StablePose", "footprint", "stable_poses"]

SCENES = ("floating", "tabletop")
MAX_STABLE_POSES = 16
#: deg: rest poses whose table normals (object frame) lie closer than this are one pose, the
#: probabilities summed: the facets of a tessellated curved side (a 64-gon cylinder's side is one
#: pose of probability ~0.93, not 64 of 0.015 each behind its two ends)
MERGE_DEG = 10.0


@dataclass(frozen=True)
class SceneConfig(Config):
    """Where the object is when it is grasped (docs/scenes.md)."""

    kind: str = "floating"  #: "floating" (in space, gravity off) or "tabletop" (resting on a table in its stable poses)
    stable_poses: int = 1  #: tabletop: stable poses per object, the most probable first (fewer if it has fewer)

    def __post_init__(self):
        if self.kind not in SCENES:
            raise ConfigError(f"scene.kind must be one of {list(SCENES)}, got {self.kind!r}")
        if not 1 <= self.stable_poses <= MAX_STABLE_POSES:
            raise ConfigError(f"scene.stable_poses must be in 1..{MAX_STABLE_POSES}, got {self.stable_poses}")

    @property
    def tabletop(self) -> bool:
        return self.kind == "tabletop"


@dataclass(frozen=True)
class StablePose:
    """One rest pose of an object on the table (normalized units: multiply lengths by the scale).

    ``transform`` (4, 4): object frame -> table frame; ``probability``: trimesh's estimate of how
    often a random drop ends in it; ``index``: its rank (0 the most probable)."""

    index: int
    transform: np.ndarray
    probability: float

    @property
    def normal(self) -> np.ndarray:
        """(3,) the table's up direction in the object frame (unit)."""
        return self.transform[2, :3].copy()

    def plane(self, scale: float) -> np.ndarray:
        """(4,) ``[n, d]`` at ``scale`` m per unit: the height above the table of an object-frame
        point x (m) is ``n . x + d``."""
        return np.array([*self.normal, self.transform[2, 3] * scale])

    def pose7(self, scale: float) -> np.ndarray:
        """(7,) the object's pose in the table frame at ``scale``: ``[x y z qw qx qy qz]`` (m)."""
        import trimesh

        q = trimesh.transformations.quaternion_from_matrix(self.transform)
        q = q if q[0] >= 0 else -q
        return np.array([*(self.transform[:3, 3] * scale), *q])


def stable_poses(vertices: np.ndarray, faces: np.ndarray, centre_of_mass: np.ndarray, count: int,
                 object_id: str = "object") -> list[StablePose]:
    """The ``count`` most probable stable poses of a mesh ``(V, 3)``, ``(F, 3)`` with its centre
    of mass ``(3,)`` (same units), most probable first; fewer if it has fewer. Deterministic
    (trimesh's quasi-static estimate, no sampling). Rest facets closer than `MERGE_DEG` are one
    pose (their summed probability, the most probable facet's transform). Raises ValueError
    naming the object if it has none."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces), process=False)
    transforms, probs = trimesh.poses.compute_stable_poses(mesh, center_mass=np.asarray(centre_of_mass, float),
                                                           sigma=0.0, n_samples=1, threshold=0.0)
    if len(transforms) == 0:
        raise ValueError(f"{object_id}: no stable pose on a plane (a degenerate convex hull?)")
    transforms, probs = np.asarray(transforms, dtype=np.float64), np.asarray(probs, dtype=np.float64)
    groups = _merge_neighbours(transforms[:, 2, :3], MERGE_DEG)
    total = np.array([probs[g].sum() for g in groups])
    best = [g[int(np.argmax(probs[g]))] for g in groups]  # each family's most probable facet
    order = np.argsort(-total, kind="stable")[:count]
    return [StablePose(k, transforms[best[i]], float(total[i])) for k, i in enumerate(order)]


def _merge_neighbours(normals: np.ndarray, max_deg: float) -> list[list[int]]:
    """Indices of ``normals`` (N, 3) in groups linked by pairs less than ``max_deg`` apart
    (single linkage), in order of their first member."""
    N = len(normals)
    parent = list(range(N))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    close = normals @ normals.T > np.cos(np.radians(max_deg))
    for i, j in zip(*np.nonzero(np.triu(close, 1))):
        parent[root(int(j))] = root(int(i))
    groups: dict[int, list[int]] = {}
    for i in range(N):
        groups.setdefault(root(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])


@dataclass(frozen=True)
class Footprint:
    """An object's extent on its table (metres, object frame): ``height`` its top above the
    table, ``width`` its narrowest horizontal extent (calipers) and ``length`` its extent at
    right angles to that, ``up`` (3,) the table's up direction, ``axis`` (3,) the horizontal
    direction of ``width`` (unit), ``centre`` (3,) the middle of both spans on the table
    (height 0)."""

    height: float
    width: float
    length: float
    up: np.ndarray
    axis: np.ndarray
    centre: np.ndarray


def footprint(points: np.ndarray, plane) -> Footprint:
    """The `Footprint` of an object's points ``(N, 3)`` (m, object frame) on the plane ``[n, d]``
    (4,) (`StablePose.plane`). The narrowest width is exact: it lies across one edge of the
    points' convex hull on the table (rotating calipers)."""
    from scipy.spatial import ConvexHull

    pts = np.asarray(points, dtype=np.float64)
    n, d = np.asarray(plane[:3], dtype=np.float64), float(plane[3])
    e1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    flat = np.stack([pts @ e1, pts @ e2], -1)  # (N, 2) on the table
    ring = flat[ConvexHull(flat).vertices]
    edge = np.roll(ring, -1, axis=0) - ring
    across = np.stack([-edge[:, 1], edge[:, 0]], -1) / np.linalg.norm(edge, axis=-1, keepdims=True)  # (E, 2)
    proj = ring @ across.T
    i = int(np.argmin(proj.max(0) - proj.min(0)))
    a2 = across[i]
    b2 = np.array([-a2[1], a2[0]])
    pa, pb = ring @ a2, ring @ b2
    mid2 = 0.5 * (pa.max() + pa.min()) * a2 + 0.5 * (pb.max() + pb.min()) * b2
    axis = a2[0] * e1 + a2[1] * e2
    centre = mid2[0] * e1 + mid2[1] * e2 - d * n
    return Footprint(float((pts @ n + d).max()), float(pa.max() - pa.min()), float(pb.max() - pb.min()), n, axis,
                     centre)
