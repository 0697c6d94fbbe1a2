"""Simulated grasp execution and the hold tests (six directions or a task's disturbance).

Execution (``close_hand``): from rest at the pregrasp (object at its initial pose), the mocap
target and the position-actuator targets move pregrasp -> grasp in ``waypoints`` linear steps
(root position linear, orientation slerp) each held ``steps_per_waypoint`` steps, then grasp
-> squeeze the same way. The closing is the same for every direction, so it is simulated once
and the full MjData state is copied into one MjData per direction: MuJoCo is deterministic,
so this equals resetting and re-running it per direction, as the public protocol does.

Hold (``hold``): each direction applies its wrench at the object's centre of mass for
``hold_steps``, the object pose being checked every ``check_every`` steps against the pose at
the reset. Directions advance in lockstep, check by check, either one after another in this
thread or on a thread pool (MuJoCo releases the GIL inside ``mj_step``); with
``stop_at_first_failure`` every direction stops at the first check where any fails. The
results are therefore identical, bit for bit, for any number of threads.

Early pass (``settle_checks`` > 0; on by default, 0 runs the full hold): a held object creeps
under its load (soft contacts), by ~0.01-0.3 mm and ~0.01-0.1 deg per check on real-object Shadow
grasps, slowing down, and never comes fully to rest (the hand's joint velocities stay above 3e-3).
A direction then passes once, at that many consecutive checks, its creep since the previous
check, continued ``settle_safety`` times faster through every remaining check, would still stay
below the failure thresholds; an object still accelerating (its creep growing) keeps being
simulated. A grasp that sits still and then gives way late in the hold (a stick-slip) is what
it cannot see; the default safety keeps twice the margin such grasps needed on the measured
rows (EvalConfig, benchmarks/results/eval.md), where its verdicts equal the full hold's.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np

from datagen.rotation import quat_angle_np

from .config import EvalConfig
from .scene import Scene

__all__ = ["DirectionResult", "close_hand", "hold", "initial_state", "slerp"]


def slerp(q0: np.ndarray, q1: np.ndarray, t: float) -> np.ndarray:
    """Unit quaternion [w x y z] between q0 (t=0) and q1 (t=1) on the shorter arc."""
    q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    dot = float(q0 @ q1)
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + t * (q1 - q0)
        return q / np.linalg.norm(q)
    th = np.arccos(dot)
    return (np.sin((1 - t) * th) * q0 + np.sin(t * th) * q1) / np.sin(th)


def _set_targets(scene: Scene, data: mujoco.MjData, pos: np.ndarray, quat: np.ndarray, joints: np.ndarray) -> None:
    pos, quat = scene.root_target(pos, quat, joints)
    data.mocap_pos[scene.mocap] = pos
    data.mocap_quat[scene.mocap] = quat
    data.ctrl[scene.actuators] = scene.ctrl(joints)


def initial_state(scene: Scene, data: mujoco.MjData, pregrasp: np.ndarray) -> None:
    """Reset ``data`` to rest with the hand at ``pregrasp`` (7 + J) and the object at its initial pose."""
    m = scene.model
    mujoco.mj_resetData(m, data)
    q = pregrasp[3:7] / np.linalg.norm(pregrasp[3:7])
    pos, quat = scene.root_target(pregrasp[:3], q, pregrasp[7:])
    data.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = pos
    data.qpos[scene.hand_free_qpos + 3:scene.hand_free_qpos + 7] = quat
    data.qpos[scene.hand_qpos_adr] = scene.hand_joints(pregrasp[7:])
    _set_targets(scene, data, pregrasp[:3], q, pregrasp[7:])
    mujoco.mj_forward(m, data)


def close_hand(scene: Scene, data: mujoco.MjData, poses: np.ndarray, cfg: EvalConfig) -> None:
    """Run pregrasp -> grasp -> squeeze on ``data`` (already at `initial_state`); poses (3, 7 + J)."""
    m = scene.model
    for a, b in ((poses[0], poses[1]), (poses[1], poses[2])):
        for k in range(1, cfg.waypoints + 1):
            t = k / cfg.waypoints
            _set_targets(scene, data, a[:3] + t * (b[:3] - a[:3]), slerp(a[3:7], b[3:7], t),
                         a[7:] + t * (b[7:] - a[7:]))
            mujoco.mj_step(m, data, nstep=cfg.steps_per_waypoint)


@dataclass(frozen=True)
class DirectionResult:
    """One direction's outcome. ``success`` None: stopped early because another direction failed.
    ``translation_m`` / ``rotation_deg``: the largest object displacement seen at the checks;
    ``unstable``: the simulation diverged (non-finite state or MuJoCo's bad-qacc reset)."""

    success: bool | None
    translation_m: float
    rotation_deg: float
    unstable: bool = False


def _pose_error(scene: Scene, data: mujoco.MjData, pos0: np.ndarray, quat0: np.ndarray) -> tuple[float, float]:
    b = scene.object_body
    t = float(np.linalg.norm(data.xpos[b] - pos0))
    return t, float(np.degrees(quat_angle_np(data.xquat[b], quat0)))


def hold(scene: Scene, closed: mujoco.MjData, wrenches: np.ndarray, datas: list[mujoco.MjData],
         pos0: np.ndarray, quat0: np.ndarray, cfg: EvalConfig,
         pool: ThreadPoolExecutor | None = None) -> list[DirectionResult]:
    """Hold test of the closed grasp ``closed`` under each wrench (D, 6) [N, N m].

    ``datas``: D scratch MjData of ``scene.model``; pos0 (3,) / quat0 (4,): the object's
    initial pose. See the module docstring for the lockstep schedule."""
    m = scene.model
    D = len(wrenches)
    bad = int(mujoco.mjtWarning.mjWARN_BADQACC)
    for d, w in zip(datas, wrenches):
        mujoco.mj_copyData(d, m, closed)
        d.xfrc_applied[:] = 0
        d.xfrc_applied[scene.object_body] = w
    active = list(range(D))
    status: list[bool | None] = [None] * D
    worst_t, worst_r = np.zeros(D), np.zeros(D)
    unstable = [False] * D
    settle = cfg.settle_checks > 0
    if settle:  # the object's pose at the previous check, and for how many checks it has crept slowly
        last_pos = [closed.xpos[scene.object_body].copy() for _ in range(D)]
        last_quat = [closed.xquat[scene.object_body].copy() for _ in range(D)]
        still = [0] * D

    def advance(i: int) -> None:
        mujoco.mj_step(m, datas[i], nstep=cfg.check_every)

    checks = cfg.hold_steps // cfg.check_every
    for k in range(checks):
        if pool is None or len(active) == 1:
            for i in active:
                advance(i)
        else:
            list(pool.map(advance, active))
        failed_now = False
        for i in active:
            d = datas[i]
            if d.warning[bad].number > closed.warning[bad].number or not np.all(np.isfinite(d.qpos)):
                unstable[i], status[i], failed_now = True, False, True
                worst_t[i], worst_r[i] = np.inf, np.inf
                continue
            t, r = _pose_error(scene, d, pos0, quat0)
            worst_t[i], worst_r[i] = max(worst_t[i], t), max(worst_r[i], r)
            if t >= cfg.max_translation_m or r >= cfg.max_rotation_deg:
                status[i], failed_now = False, True
            elif settle:
                b = scene.object_body
                moved = float(np.linalg.norm(d.xpos[b] - last_pos[i]))
                turned = float(np.degrees(quat_angle_np(d.xquat[b], last_quat[i])))
                last_pos[i], last_quat[i] = d.xpos[b].copy(), d.xquat[b].copy()
                left = (checks - 1 - k) * cfg.settle_safety  # the remaining checks, with a safety factor
                slow = t + left * moved < cfg.max_translation_m and r + left * turned < cfg.max_rotation_deg
                still[i] = still[i] + 1 if slow else 0
                if still[i] >= cfg.settle_checks:
                    status[i] = True
        active = [i for i in active if status[i] is None]
        if (failed_now and cfg.stop_at_first_failure) or not active:
            break
    else:
        for i in active:
            status[i] = True
    return [DirectionResult(status[i], float(worst_t[i]), float(worst_r[i]), unstable[i]) for i in range(D)]
