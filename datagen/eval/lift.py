"""The tabletop test: grasp an object resting on a table under a gravity-equivalent force, then lift.

DexGraspBench's ``tabletop`` setting (NOTES §8), in this project's scene (world = object frame,
the table the plane of the row's ``support_plane``, `datagen.eval.scene`): a force of
``force_per_kg`` x mass (1 N for 0.1 kg) along the table's down direction acts on the object's
centre of mass from the start; the hand is driven pregrasp -> grasp, then grasp -> squeeze
(two linear stages, `close_hand`), then the mocap target rises ``lift_m`` along the table's
normal in ``waypoints`` x ``steps_per_waypoint`` steps, the joints held at the squeeze. The
grasp passes when the object ends within ``max_translation_m`` and ``max_rotation_deg`` of its
initial pose raised by ``lift_m``. Gravity stays off, as in the peer's scene: the force is the
gravity, so a table in any orientation of the object frame is the same test.

Why it fails (`lift_reason`): ``object_left_on_table`` (the object never rose half the lift),
``object_dropped`` (it rose that far, then ended below it), ``object_slipped`` (lifted, but moved
or turned past a threshold in the hand); `datagen.eval.evaluate` rejects ``hand_in_table``
(a hand geom deeper than ``max_table_penetration_m`` in the table at the pregrasp or the grasp)
before simulating.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from datagen.rotation import quat_angle_np

from .config import EvalConfig
from .hold import DirectionResult, close_hand, initial_state
from .metrics import set_static_pose
from .scene import Scene

__all__ = ["LIFT_TEST", "LiftResult", "lift", "lift_reason", "table_depth", "table_normal"]

LIFT_TEST = "tabletop_lift"


@dataclass(frozen=True)
class LiftResult:
    """The lift's outcome: ``direction`` (success, the final distance from the raised initial pose
    in m and deg, unstable), ``max_rise_m``/``end_rise_m``: the object's highest and final rise
    along the table normal (m); ``steps``: MuJoCo steps simulated."""

    direction: DirectionResult
    max_rise_m: float
    end_rise_m: float
    steps: int


def table_normal(scene: Scene) -> np.ndarray | None:
    """(3,) the table's up direction in the scene (object) frame; None without a table."""
    if len(scene.table_geoms) == 0:
        return None
    z = np.zeros(3)
    mujoco.mju_rotVecQuat(z, np.array([0.0, 0.0, 1.0]), scene.model.geom_quat[int(scene.table_geoms[0])])
    return z


def table_depth(scene: Scene, data: mujoco.MjData, row: np.ndarray, distmax: float = 0.01) -> float:
    """Max depth (m, >= 0) of the hand's collision geoms in the table with the hand at ``row``
    (7 + J); 0 without a table."""
    if len(scene.table_geoms) == 0:
        return 0.0
    set_static_pose(scene, data, row)
    m, depth = scene.model, 0.0
    for g in scene.hand_geoms:
        for t in scene.table_geoms:
            depth = max(depth, -mujoco.mj_geomDistance(m, data, int(g), int(t), distmax, None))
    return depth


def lift(scene: Scene, data: mujoco.MjData, poses: np.ndarray, normal: np.ndarray, cfg: EvalConfig) -> LiftResult:
    """Run the tabletop test on ``data`` for poses (3, 7 + J) [pregrasp, grasp, squeeze] (object
    frame) and the table's unit up direction ``normal`` (3,) (object frame); see the module docstring."""
    m, b = scene.model, scene.object_body
    n = np.asarray(normal, dtype=np.float64)
    initial_state(scene, data, poses[0])
    pos0, quat0 = data.xpos[b].copy(), data.xquat[b].copy()
    data.xfrc_applied[b, :3] = -cfg.force_per_kg * scene.object_mass * n
    close_hand(scene, data, poses, cfg)
    sq = poses[2]
    top = sq[:3] + cfg.lift_m * n
    rise = []
    q = sq[3:7] / np.linalg.norm(sq[3:7])
    for k in range(1, cfg.waypoints + 1):
        t = k / cfg.waypoints
        pos, quat = scene.root_target(sq[:3] + t * (top - sq[:3]), q, sq[7:])
        data.mocap_pos[scene.mocap], data.mocap_quat[scene.mocap] = pos, quat
        mujoco.mj_step(m, data, nstep=cfg.steps_per_waypoint)
        rise.append(float(n @ (data.xpos[b] - pos0)))
    steps = int(round(data.time / cfg.timestep_s))
    if data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number or not np.all(np.isfinite(data.qpos)):
        return LiftResult(DirectionResult(False, np.inf, np.inf, True), max(rise), rise[-1], steps)
    moved = float(np.linalg.norm(data.xpos[b] - (pos0 + cfg.lift_m * n)))
    turned = float(np.degrees(quat_angle_np(data.xquat[b], quat0)))
    ok = moved < cfg.max_translation_m and turned < cfg.max_rotation_deg
    return LiftResult(DirectionResult(ok, moved, turned), max(rise), rise[-1], steps)


def lift_reason(res: LiftResult, cfg: EvalConfig) -> str | None:
    """The reason code of a lift (None: it passed); see the module docstring."""
    d = res.direction
    if d.success:
        return None
    if d.unstable:
        return "unstable"
    if res.max_rise_m < 0.5 * cfg.lift_m:
        return "object_left_on_table"
    if res.end_rise_m < 0.5 * cfg.lift_m:
        return "object_dropped"
    return "object_slipped"
