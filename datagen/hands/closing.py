"""Which way a hand's joints close, from its kinematics and joint ranges (MuJoCo model and data).

A finger's joint closes towards the side of its range that is larger in magnitude (a flexion range
of 0..1.6 rad, with at most a little hyperextension): every built-in hand and every URDF measured
so far. A joint whose range is symmetric (the D'Claw's +-1.57 rad) says nothing by its range; it
closes the way that moves the fingertips below it towards the fingertips' centroid, the hand's
grasp centre (a claw's fingers close on one another). Used by `hand init` for the pad side and by
`hand check` for the palm's and the pads' checks, so the two agree.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["SYMMETRIC_RANGE", "ancestors", "closing_signs", "link_centre"]

SYMMETRIC_RANGE = 0.1  # |hi| and |lo| within this fraction of the larger: the range does not say


def link_centre(data: mujoco.MjData, body: int, shapes) -> np.ndarray:
    """(3,) world position of the area-weighted centroid of a link's collision shapes
    (`geometry.link_shapes`), its body origin without any: a fingertip's position (its origin is
    often its joint's anchor, which the joint does not move)."""
    if not shapes:
        return data.xpos[body].copy()
    areas = np.array([s.mesh.area for s in shapes])
    local = (np.array([s.mesh.centroid for s in shapes]) * areas[:, None]).sum(0) / areas.sum()
    return data.xpos[body] + data.xmat[body].reshape(3, 3) @ local


def ancestors(model: mujoco.MjModel, body: int) -> list[int]:
    """``[body, its parent, ..., 0 (the world)]``."""
    out = [body]
    while body != 0:
        body = int(model.body_parentid[body])
        out.append(body)
    return out


def closing_signs(model: mujoco.MjModel, data: mujoco.MjData, tips: list[int],
                  points: list[np.ndarray]) -> np.ndarray:
    """(njnt,) +1 or -1 per joint: the direction (in joint coordinates) in which it closes.

    tips: fingertip body ids; points (each (3,), world): a point on each (`link_centre`), whose
    motion decides a symmetric-range joint: towards their centroid. A symmetric joint with no
    fingertip below it, an unlimited one or one that moves its fingertips only across the centre
    gets +1. ``data`` holds the pose (kinematics computed)."""
    pts = [np.asarray(p, dtype=np.float64) for p in points]
    centre = np.mean(pts, axis=0)
    out = np.ones(model.njnt)
    for j in range(model.njnt):
        lo, hi = model.jnt_range[j] if model.jnt_limited[j] else (-1.0, 1.0)
        big = max(abs(lo), abs(hi))
        if big > 0 and abs(abs(hi) - abs(lo)) > SYMMETRIC_RANGE * big:
            out[j] = 1.0 if abs(hi) > abs(lo) else -1.0
            continue
        if not model.jnt_limited[j]:
            continue
        inward = 0.0
        for b, p in zip(tips, pts):
            if int(model.jnt_bodyid[j]) in ancestors(model, b):
                if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
                    move = np.cross(data.xaxis[j], p - data.xanchor[j])
                else:
                    move = data.xaxis[j].copy()
                inward += float(move @ (centre - p))
        out[j] = -1.0 if inward < 0 else 1.0
    return out
