"""Static metrics of a hand pose against the object, from ``mujoco.mj_geomDistance``.

All at a kinematic pose (no dynamics): the hand at a qpos row, the object at the origin.
Distances are signed, metres (negative = penetration depth). Shapes: G hand collision geoms,
F fingertips, m contacts.

* hand-object distance per hand geom, with the nearest points on both sides;
* penetration = max depth over hand-object geom pairs and hand-scenery geom pairs (a task's
  static door, housing or cabinet; 0 when nothing overlaps);
* self penetration = max depth over pairs of hand collision geoms on bodies that are neither
  the same nor parent and child (MuJoCo's own exclusion; the hand's <exclude> pairs too), and
  that do not already overlap at the hand's open pose (structural overlaps of the collision
  model, e.g. the Shadow palm box and the proximal capsules);
* per-finger contact distance = min distance of the fingertip link's geoms to the object;
* epsilon contacts: for each hand geom within ``contact_distance_m``, the nearest point on the
  object and the unit normal there pointing into the object.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from .scene import Scene

__all__ = ["StaticMetrics", "set_static_pose", "hand_object_distances", "self_penetration", "static_metrics",
           "self_pairs", "scenery_penetration"]


def set_static_pose(scene: Scene, data: mujoco.MjData, row: np.ndarray) -> None:
    """Put the hand at ``row`` (7 + J) [x y z qw qx qy qz, joints] and the object at its initial
    pose, and compute the kinematics (geom poses) only."""
    m = scene.model
    data.qpos[:] = m.qpos0
    q = np.asarray(row[3:7], dtype=np.float64)
    pos, q = scene.root_target(row[:3], q / np.linalg.norm(q), row[7:])
    data.qpos[scene.hand_free_qpos:scene.hand_free_qpos + 3] = pos
    data.qpos[scene.hand_free_qpos + 3:scene.hand_free_qpos + 7] = q
    data.qpos[scene.hand_qpos_adr] = scene.hand_joints(row[7:])
    data.mocap_pos[scene.mocap] = pos
    data.mocap_quat[scene.mocap] = q
    mujoco.mj_kinematics(m, data)


def _bound_filter(m, d, g1: int, g2: np.ndarray, distmax: float) -> np.ndarray:
    """Geoms of ``g2`` whose bounding spheres come within ``distmax`` of geom ``g1``'s."""
    gap = np.linalg.norm(d.geom_xpos[g2] - d.geom_xpos[g1], axis=1) - m.geom_rbound[g2] - m.geom_rbound[g1]
    return g2[gap < distmax]


def hand_object_distances(scene: Scene, data: mujoco.MjData, distmax: float):
    """Per hand collision geom: signed distance (G,) m (capped at ``distmax``), nearest hand
    point (G, 3) and nearest object point (G, 3) (NaN where nothing is within ``distmax``)."""
    m = scene.model
    G = len(scene.hand_geoms)
    dist = np.full(G, distmax)
    p_hand = np.full((G, 3), np.nan)
    p_obj = np.full((G, 3), np.nan)
    fromto = np.zeros(6)
    for i, g in enumerate(scene.hand_geoms):
        for o in _bound_filter(m, data, int(g), scene.object_geoms, distmax):
            fromto[:] = 0
            dd = mujoco.mj_geomDistance(m, data, int(g), int(o), distmax, fromto)
            if dd < dist[i]:
                dist[i] = dd
                p_hand[i], p_obj[i] = fromto[:3], fromto[3:]
    return dist, p_hand, p_obj


def scenery_penetration(scene: Scene, data: mujoco.MjData) -> float:
    """Max depth (m, >= 0) of the hand's collision geoms inside the scene's static scenery."""
    m = scene.model
    depth = 0.0
    if len(scene.scenery_geoms) == 0:
        return depth
    for g in scene.hand_geoms:
        for e in _bound_filter(m, data, int(g), scene.scenery_geoms, 0.0):
            depth = max(depth, -mujoco.mj_geomDistance(m, data, int(g), int(e), 0.0, None))
    return depth


def self_pairs(scene: Scene) -> np.ndarray:
    """(S, 2) hand collision geom pairs checked for self penetration (see module docstring)."""
    if scene.self_pairs is None:
        m = scene.model
        excluded = {int(s) for s in m.exclude_signature}
        pairs = []
        geoms = scene.hand_geoms
        for a in range(len(geoms)):
            for b in range(a + 1, len(geoms)):
                ga, gb = int(geoms[a]), int(geoms[b])
                ba, bb = int(m.geom_bodyid[ga]), int(m.geom_bodyid[gb])
                if ba == bb or m.body_parentid[ba] == bb or m.body_parentid[bb] == ba:
                    continue
                if ((min(ba, bb) << 16) + max(ba, bb)) in excluded:
                    continue
                pairs.append((ga, gb))
        data = mujoco.MjData(m)
        hand = scene.hand
        set_static_pose(scene, data, np.concatenate([[0, 0, 0, 1, 0, 0, 0], hand.open_pose.cpu().numpy()]))
        pairs = [(a, b) for a, b in pairs if mujoco.mj_geomDistance(m, data, a, b, 1e-3, None) > 0]
        scene.self_pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return scene.self_pairs


def self_penetration(scene: Scene, data: mujoco.MjData) -> float:
    """Max self-penetration depth (m, >= 0) of the hand at the pose in ``data``."""
    m = scene.model
    pairs = self_pairs(scene)
    a, b = pairs[:, 0], pairs[:, 1]
    # pairs whose bounding spheres overlap (a margin above 0: a pair more is one more exact query)
    gap = np.linalg.norm(data.geom_xpos[a] - data.geom_xpos[b], axis=1) - m.geom_rbound[a] - m.geom_rbound[b]
    depth = 0.0
    for ga, gb in pairs[gap < 1e-9]:
        d = mujoco.mj_geomDistance(m, data, int(ga), int(gb), 0.0, None)
        depth = max(depth, -d)
    return depth


@dataclass(frozen=True)
class StaticMetrics:
    """Metrics of one pose (metres): ``penetration`` >= 0, ``self_penetration`` >= 0,
    ``min_distance`` signed, ``finger_distance`` (F,) signed in ``hand.fingertip_names`` order
    (capped at the query's distmax), ``touching_links`` the number of hand links within the
    touch distance, ``contact_points`` / ``contact_normals`` (m, 3) for the epsilon metric."""

    penetration: float
    self_penetration: float
    min_distance: float
    finger_distance: np.ndarray
    touching_links: int
    contact_points: np.ndarray
    contact_normals: np.ndarray


def static_metrics(scene: Scene, data: mujoco.MjData, row: np.ndarray, *, touch_distance: float,
                   contact_distance: float, distmax: float = 0.05, with_self: bool = True) -> StaticMetrics:
    """All static metrics of the hand at ``row`` (7 + J) against the object at the origin."""
    set_static_pose(scene, data, row)
    dist, p_hand, p_obj = hand_object_distances(scene, data, max(distmax, contact_distance))
    links = scene.hand_geom_link
    hand = scene.hand
    finger = np.full(len(hand.fingertip_names), max(distmax, contact_distance))
    tip_links = hand.fingertip_link_index.cpu().numpy()
    for f, li in enumerate(tip_links):
        sel = links == li
        if sel.any():
            finger[f] = dist[sel].min()
    close = dist <= contact_distance
    pts, nrm = [], []
    for i in np.flatnonzero(close):
        v = p_obj[i] - p_hand[i]
        n = np.linalg.norm(v)
        if n < 1e-9:  # exactly touching: the segment has no direction, use the geom centre
            v = p_obj[i] - data.geom_xpos[scene.hand_geoms[i]]
            n = np.linalg.norm(v)
            if n < 1e-9:
                continue
        elif dist[i] < 0:  # penetrating: the segment runs from inside the object outwards
            v = -v
        pts.append(p_obj[i])
        nrm.append(v / n)
    return StaticMetrics(
        penetration=max(float(max(0.0, -dist.min())) if len(dist) else 0.0, scenery_penetration(scene, data)),
        self_penetration=self_penetration(scene, data) if with_self else 0.0,
        min_distance=float(dist.min()) if len(dist) else float(distmax),
        finger_distance=finger,
        touching_links=int(len(np.unique(links[dist <= touch_distance]))),
        contact_points=np.asarray(pts, dtype=np.float64).reshape(-1, 3),
        contact_normals=np.asarray(nrm, dtype=np.float64).reshape(-1, 3),
    )
