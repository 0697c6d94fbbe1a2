"""A row's hand and object as posed meshes, from the evaluation's own MuJoCo scene.

The scene is `datagen.eval.build_scene` of the row's hand, processed object (its convex
pieces at the row's scale) and task, with the evaluation config the rows were simulated with,
and a tabletop row's table (part ``table``, a thin slab whose top is the plane): the page shows
what was simulated. Each geom becomes one `Geom` (a mesh in its own frame:
MuJoCo's compiled mesh vertices, or a primitive tessellated by trimesh), and a pose of the
hand is a (G, 3) position and (G, 4) quaternion per geom, read from MuJoCo's kinematics
(``set_static_pose``, the same call the evaluation's static metrics use). MuJoCo's kinematics
of this model equal the project's FK (`HandModel.link_transforms`, checked at hand load).

States: ``pregrasp``, ``grasp``, ``squeeze`` (the actuator target, placed kinematically) and
``simulated``: the scene after the evaluation's closing, pregrasp -> grasp -> squeeze
(`datagen.eval.hold.close_hand`), where the object may have moved; for a tabletop row after
the lift test's closing under its gravity-equivalent force and the lift (`datagen.eval.lift`).
Lengths in metres.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import trimesh

from datagen.eval import EvalConfig, EvalError, build_scene, pieces_from_processed
from datagen.eval.hold import close_hand, initial_state
from datagen.eval.lift import lift, table_normal
from datagen.eval.metrics import set_static_pose
from datagen.eval.scene import HAND_PREFIX, Scene

from .source import ViewError

__all__ = ["STATES", "Geom", "PosedGrasp", "SceneCache", "scene_geoms", "geom_poses"]

STATES = ("pregrasp", "grasp", "squeeze", "simulated")
_G = mujoco.mjtGeom


@dataclass(frozen=True)
class Geom:
    """One drawable geom: ``vertices`` (V, 3) m in the geom frame, ``faces`` (F, 3), ``rgba`` (4,)
    in 0..1; ``part`` ``hand`` or ``object``; ``collision`` whether it takes part in contacts;
    ``index`` its MuJoCo geom id."""

    name: str
    part: str
    collision: bool
    vertices: np.ndarray
    faces: np.ndarray
    rgba: np.ndarray
    index: int


def _primitive(kind: int, size: np.ndarray) -> trimesh.Trimesh | None:
    if kind == _G.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    if kind == _G.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[12, 12])
    if kind == _G.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1], sections=16)
    if kind == _G.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * size)
    if kind == _G.mjGEOM_ELLIPSOID:
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        m.apply_scale(size)
        return m
    return None  # planes, heightfields, SDFs: not drawn


def scene_geoms(scene: Scene) -> list[Geom]:
    """Every drawable hand, object and table geom of ``scene`` (see module docstring)."""
    m = scene.model
    obj = set(int(g) for g in scene.object_geoms)
    table = set(int(g) for g in scene.table_geoms)
    out = []
    for g in range(m.ngeom):
        body = m.body(m.geom_bodyid[g]).name
        part = "object" if g in obj else ("hand" if body.startswith(HAND_PREFIX) else "table" if g in table else None)
        if part is None:
            continue
        kind = int(m.geom_type[g])
        if part == "table":  # the plane as a slab 2 mm thick, its top face the plane (z = 0 of the geom)
            slab = trimesh.creation.box(extents=[2 * m.geom_size[g][0], 2 * m.geom_size[g][1], 0.002])
            slab.apply_translation([0, 0, -0.001])
            verts, faces = np.asarray(slab.vertices), np.asarray(slab.faces)
        elif kind == _G.mjGEOM_MESH:
            k = int(m.geom_dataid[g])
            va, vn = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
            fa, fn = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
            verts, faces = m.mesh_vert[va:va + vn].copy(), m.mesh_face[fa:fa + fn].copy()
        else:
            mesh = _primitive(kind, m.geom_size[g])
            if mesh is None:
                continue
            verts, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        mat = int(m.geom_matid[g])
        rgba = m.mat_rgba[mat] if mat >= 0 else m.geom_rgba[g]
        out.append(Geom(m.geom(g).name or f"geom{g}", part, bool(m.geom_contype[g] or m.geom_conaffinity[g]),
                        verts.astype(np.float32), faces.astype(np.int32), np.asarray(rgba, dtype=np.float64), g))
    return out


def geom_poses(model: mujoco.MjModel, data: mujoco.MjData, geoms: list[Geom]) -> tuple[np.ndarray, np.ndarray]:
    """World positions (G, 3) m and quaternions (G, 4) [w x y z] of ``geoms`` in ``data``."""
    idx = np.array([g.index for g in geoms], dtype=np.int64)
    pos = data.geom_xpos[idx].copy()
    quat = np.zeros((len(idx), 4))
    for i, g in enumerate(idx):
        mujoco.mju_mat2Quat(quat[i], data.geom_xmat[g])
    return pos, quat


@dataclass
class PosedGrasp:
    """A row in its scene: ``geoms`` and, per state of `STATES`, their poses (lazily simulated)."""

    scene: Scene
    geoms: list[Geom]
    poses: np.ndarray  # (3, 7 + J) pregrasp, grasp, squeeze
    cfg: EvalConfig
    _cache: dict | None = None

    def state(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Positions (G, 3) m and quaternions (G, 4) of every geom in state ``name``, and the
        object body's position (3,) and quaternion (4,) (moved only in ``simulated``)."""
        if name not in STATES:
            raise ValueError(f"unknown state {name!r}; states: {STATES}")
        if self._cache is None:
            self._cache = {}
        if name not in self._cache:
            m = self.scene.model
            data = mujoco.MjData(m)
            if name == "simulated" and len(self.scene.table_geoms):
                lift(self.scene, data, self.poses, table_normal(self.scene), self.cfg)
                mujoco.mj_kinematics(m, data)
            elif name == "simulated":
                initial_state(self.scene, data, self.poses[0])
                close_hand(self.scene, data, self.poses, self.cfg)
                mujoco.mj_kinematics(m, data)
            else:
                set_static_pose(self.scene, data, self.poses[STATES.index(name)])
            b = self.scene.object_body
            self._cache[name] = (*geom_poses(m, data, self.geoms), data.xpos[b].copy(), data.xquat[b].copy())
        return self._cache[name]


class SceneCache:
    """Hands and scenes by (hand, object, scale, task), most recently used kept (``size``). Hands
    are loaded as the rows of ``base`` name them (a job directory or a table's folder: its pinned
    hands first, `datagen.hands.load_hand`)."""

    def __init__(self, eval_config: dict | None = None, size: int = 8, base: Path | None = None) -> None:
        self.base = base
        try:
            self.cfg = EvalConfig.from_dict(eval_config or {})
        except EvalError:
            self.cfg = EvalConfig()  # written by another version: the defaults (the public protocol)
        self._hands: dict[str, object] = {}
        self._scenes: OrderedDict = OrderedDict()
        self._size = size

    def hand(self, name: str):
        from datagen.hands import HandSpecError, load_hand

        if name not in self._hands:
            try:
                self._hands[name] = load_hand(name, base=self.base)
            except HandSpecError as exc:
                raise ViewError(f"hand {name!r}", str(exc)) from None
        return self._hands[name]

    def posed(self, hand: str, object_dir: Path, scale: float, task: str, poses: np.ndarray,
              table: tuple | None = None) -> PosedGrasp:
        """The `PosedGrasp` of one row (scene built once per hand, object, scale, task and
        table: a tabletop row's support plane, None floating)."""
        from datagen.objects import load_processed

        key = (hand, str(object_dir), float(scale), task, table)
        if key not in self._scenes:
            try:
                processed = load_processed(Path(object_dir))
                pieces = pieces_from_processed(processed, float(scale))
            except (OSError, ValueError, KeyError) as exc:
                raise ViewError(f"object {object_dir}", f"cannot read the processed object: {exc}",
                                "object_path must point to a processed object (datagen prepare)") from None
            try:
                test = self.cfg.task_test(task)
            except EvalError:
                test = None  # a task without a test: shown on a free object
            scene = build_scene(self.hand(hand), pieces, self.cfg, None if table is not None else test, table=table)
            self._scenes[key] = (scene, scene_geoms(scene))
            while len(self._scenes) > self._size:
                self._scenes.popitem(last=False)
        self._scenes.move_to_end(key)
        scene, geoms = self._scenes[key]
        hand_model = scene.hand
        if poses.shape[-1] != 7 + hand_model.num_joints:
            raise ViewError(f"hand {hand!r}", f"rows have {poses.shape[-1]} pose values, the hand needs "
                            f"7 + {hand_model.num_joints}")
        return PosedGrasp(scene, geoms, poses, self.cfg)
