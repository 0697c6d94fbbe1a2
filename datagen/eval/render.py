"""PNG pictures of grasps for debugging and the dataset report (MuJoCo offscreen rendering).

Each picture is a grid: columns = the initial pose (hand at the pregrasp), the grasp pose, and
the simulated state after pregrasp -> grasp -> squeeze (a tabletop row: after the lift,
`datagen.eval.lift`); rows = two views of the object (from the side opposite the hand, looking
at the palm, and from 90 degrees around). A tabletop scene's table is drawn, the cameras above
it (their elevation measured from the table, not from the object frame's z).
The offscreen GL backend is MuJoCo's ``MUJOCO_GL``, read when mujoco is first imported: call
`datagen.gl.select_backend` before importing mujoco (``datagen render`` and ``datagen report`` do;
it tries ``egl``, which Mesa provides on a CPU, then ``osmesa``), or set the variable yourself.
The renderer is closed explicitly (its destructor raises at interpreter exit).
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from datagen.hands.render import write_png

from .config import EvalConfig, EvalError
from .hold import close_hand, initial_state
from .lift import lift, table_normal
from .metrics import set_static_pose
from .scene import Scene

__all__ = ["render_grasp", "grasp_frames"]


def _cameras(scene: Scene, poses: np.ndarray) -> list[mujoco.MjvCamera]:
    toward_hand = poses[1, :3] / max(np.linalg.norm(poses[1, :3]), 1e-9)
    az = float(np.degrees(np.arctan2(toward_hand[1], toward_hand[0])))
    dist = max(0.25, 5.0 * scene.objects.scale)
    up = table_normal(scene)
    cams = []
    for offset in (0.0, 90.0):  # the camera looks along its azimuth: from beyond the object towards the hand
        cam = mujoco.MjvCamera()
        cam.lookat[:] = 0.0
        cam.distance = dist
        cam.azimuth, cam.elevation = az + offset, -25.0
        if up is not None:  # looking 25 deg down onto the table, towards the hand along it
            along = toward_hand - (toward_hand @ up) * up
            along = along / np.linalg.norm(along) if np.linalg.norm(along) > 1e-6 else np.cross(up, [1.0, 0, 0])
            along = along * np.cos(np.radians(offset)) + np.cross(up, along) * np.sin(np.radians(offset))
            forward = np.cos(np.radians(25.0)) * along - np.sin(np.radians(25.0)) * up
            cam.azimuth = float(np.degrees(np.arctan2(forward[1], forward[0])))
            cam.elevation = float(np.degrees(np.arcsin(np.clip(forward[2], -1.0, 1.0))))
        cams.append(cam)
    return cams


def grasp_frames(scene: Scene, poses: np.ndarray, cfg: EvalConfig, *, width: int = 320,
                 height: int = 240) -> np.ndarray:
    """(2 * height, 3 * width, 3) uint8 image grid of one grasp (see module docstring)."""
    model = scene.model
    data = mujoco.MjData(model)
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:
        gl = os.environ.get("MUJOCO_GL", "unset")
        raise EvalError("grasp rendering", f"cannot open an offscreen GL context (MUJOCO_GL={gl} when mujoco "
                        f"was imported): {exc}", "`python -m datagen.gl` names a backend that works here; set "
                        "MUJOCO_GL to it before mujoco is imported") from None
    try:
        cams = _cameras(scene, poses)
        columns = []
        states = []
        set_static_pose(scene, data, poses[0])
        mujoco.mj_forward(model, data)
        states.append(mujoco.MjData(model))
        mujoco.mj_copyData(states[-1], model, data)
        set_static_pose(scene, data, poses[1])
        mujoco.mj_forward(model, data)
        states.append(mujoco.MjData(model))
        mujoco.mj_copyData(states[-1], model, data)
        if len(scene.table_geoms):
            lift(scene, data, poses, table_normal(scene), cfg)
        else:
            initial_state(scene, data, poses[0])
            close_hand(scene, data, poses, cfg)
        mujoco.mj_forward(model, data)
        states.append(data)
        for st in states:
            frames = []
            for cam in cams:
                renderer.update_scene(st, camera=cam)
                frames.append(renderer.render().copy())
            columns.append(np.concatenate(frames, axis=0))
        return np.concatenate(columns, axis=1)
    finally:
        renderer.close()


def render_grasp(scene: Scene, poses: np.ndarray, cfg: EvalConfig, path: str | Path, **kw) -> Path:
    """Write `grasp_frames` of ``poses`` (3, 7 + J) to ``path`` (PNG); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(path, grasp_frames(scene, poses, cfg, **kw))
    return path
