"""Grasps constructed directly with MuJoCo for the evaluation tests (no synthesis involved).

A box (convex OBJ written here, normalized units) sits in front of the open Shadow hand's palm;
each finger then closes kinematically along a fixed closing direction until its links touch
the box (bisection on ``mj_geomDistance``). The grasp is that touching configuration, the
pregrasp 70% of it (more open) and the squeeze ``2 * grasp - pregrasp`` (the successor method's
convention, ARCHITECTURE.md "Synthesis").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from datagen.eval import ObjectPieces
from datagen.eval.metrics import hand_object_distances, set_static_pose

# Shadow closing direction: flexion joints of the four fingers to 1.571 rad; the thumb to opposition.
THUMB_CLOSED = {"robot0:THJ4": 1.047, "robot0:THJ3": 1.222, "robot0:THJ2": 0.209, "robot0:THJ1": 0.524,
                "robot0:THJ0": -0.6}
PALM_FACE_Y = -0.012   # m, the palm's front in the Shadow root frame (y), at the open pose
KNUCKLE_Z = 0.385      # m, height of the finger knuckles in the Shadow root frame


def box_pieces(half_extents, directory: Path, name: str = "box") -> ObjectPieces:
    """A box with ``half_extents`` (3,) metres as one convex piece; scale = its half-diagonal."""
    half = np.asarray(half_extents, dtype=np.float64)
    s = float(np.linalg.norm(half))
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64) * half / s
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6),
             (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    path = Path(directory) / f"{name}.obj"
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in corners] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return ObjectPieces(name, (path,), (8 * float(np.prod(half / s)),), s)


def closing_target(hand) -> np.ndarray:
    names = hand.joint_names
    target = np.zeros(hand.num_joints)
    for i, n in enumerate(names):
        if n[-2:] in ("J2", "J1", "J0") and not n.startswith(("robot0:TH", "robot0:WR")):
            target[i] = 1.571
    for k, v in THUMB_CLOSED.items():
        target[names.index(k)] = v
    return target


def close_until_touch(scene, data, root: np.ndarray) -> np.ndarray:
    """(J,) joints: each finger at the first touch along its closing direction (or fully closed)."""
    hand = scene.hand
    target = closing_target(hand)
    q = np.zeros(hand.num_joints)
    for f in ("ff", "mf", "rf", "lf", "th"):
        idx = [i for i, n in enumerate(hand.joint_names) if n.startswith("robot0:" + f.upper())]
        links = [i for i, n in enumerate(hand.link_names) if n.startswith("robot0:" + f)]
        sel = np.isin(scene.hand_geom_link, links)

        def gap(t: float) -> float:
            qq = q.copy()
            qq[idx] = t * target[idx]
            set_static_pose(scene, data, np.concatenate([root, qq]))
            return float(hand_object_distances(scene, data, 0.05)[0][sel].min())

        lo, hi = 0.0, 1.0
        if gap(1.0) > 0:
            lo = 1.0
        else:
            for _ in range(25):
                mid = (lo + hi) / 2
                lo, hi = (mid, hi) if gap(mid) > 0 else (lo, mid)
        q[idx] = lo * target[idx]
    return q


def box_grasp(evaluator, half_extents, drop: float, directory: Path):
    """(pieces, poses (3, 7 + J)) of the box grasp: the box against the palm, its top ``drop``
    metres below the knuckles' reach."""
    half = np.asarray(half_extents, dtype=np.float64)
    pieces = box_pieces(half, directory, name="box_" + "_".join(f"{x * 1000:.1f}" for x in half) + f"_{drop:.3f}")
    scene, datas = evaluator.scene(pieces)
    centre = np.array([0.0, PALM_FACE_Y - half[1], KNUCKLE_Z - half[2] - 0.004 - drop])
    root = np.array([*(-centre), 1.0, 0.0, 0.0, 0.0])
    q = close_until_touch(scene, datas[-1], root)
    grasp = np.concatenate([root, q])
    pre = np.concatenate([root, 0.7 * q])
    return pieces, np.stack([pre, grasp, 2 * grasp - pre])
