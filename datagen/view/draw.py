"""Drawing one row into a viser scene: object pieces, hand geoms, contact points and normals.

Used by the live browser (`datagen.view.app`) and the static export (`datagen.view.export`).
Node names: ``/grasp/object/*`` (the convex pieces, as simulated), ``/grasp/hand/*`` (the
hand's visual meshes), ``/grasp/collision/*`` (the hand's collision geoms), and
``/grasp/contacts`` (a frame moving with the object: spheres at ``contact_points`` and arrows
along the inward ``contact_normals``, ending at the surface).
"""

from __future__ import annotations

import numpy as np

from .posing import PosedGrasp

__all__ = ["GraspDrawing", "NORMAL_LENGTH_M", "camera_for"]

NORMAL_LENGTH_M = 0.02          # drawn length of a contact normal
OBJECT_RGB = (217, 140, 51)     # the evaluation render's object colour
TABLE_RGB = (150, 125, 100)  # a tabletop row's table
HAND_RGB = (120, 130, 150)      # the hand's visual meshes (MuJoCo's near-white would vanish on the page)
COLLISION_RGB = (60, 130, 230)
CONTACT_RGB = (220, 20, 60)
NORMAL_RGB = (250, 200, 0)


def camera_for(posed: PosedGrasp) -> tuple[np.ndarray, np.ndarray]:
    """(position, look_at) of a camera on the object: from the side (100 degrees around from the
    hand's root, so the fingers and the object are seen side by side rather than the forearm)
    and 25 degrees above, at a distance that frames the fingers (metres)."""
    toward = posed.poses[1, :3].copy()
    toward[2] = 0.0
    az = np.arctan2(toward[1], toward[0]) + np.radians(100.0) if np.linalg.norm(toward) > 1e-9 else 0.0
    dist = max(0.2, 4.0 * posed.scene.objects.scale)
    el = np.radians(25.0)
    pos = dist * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return pos, np.zeros(3)


class GraspDrawing:
    """The nodes of one drawn row in ``scene`` (a viser ``SceneApi``); see module docstring."""

    def __init__(self, scene) -> None:
        self.scene = scene
        self.nodes: list = []          # one handle per geom of the drawn scene (None: not drawn)
        self.roles: list[str] = []     # "object", "hand", "collision" or "table" per geom
        self.contacts = None
        self._key = None
        self.visible = {"object": True, "hand": True, "collision": False, "contacts": True, "table": True}

    def _build(self, posed: PosedGrasp) -> None:
        self.scene.remove_by_name("/grasp")
        self.nodes, self.roles = [], []
        hand_visual = [g for g in posed.geoms if g.part == "hand" and not g.collision]
        for i, g in enumerate(posed.geoms):
            if g.part == "object":
                role, rgb, opacity = "object", OBJECT_RGB, None
            elif g.part == "table":
                role, rgb, opacity = "table", TABLE_RGB, 0.6
            elif g.collision and hand_visual:
                role, rgb, opacity = "collision", COLLISION_RGB, 0.45
            else:  # a visual mesh, or a collision geom of a hand without visual meshes
                role, rgb, opacity = "hand", HAND_RGB, None
            if g.part == "hand" and g.rgba[3] == 0:
                self.nodes.append(None)
                self.roles.append(role)
                continue
            self.nodes.append(self.scene.add_mesh_simple(
                f"/grasp/{role}/{i:03d}", g.vertices, g.faces, color=rgb, opacity=opacity,
                flat_shading=False, visible=self.visible[role]))
            self.roles.append(role)

    def show(self, posed: PosedGrasp, points, normals, state: str, key) -> None:
        """Draw ``posed`` in ``state`` with its contact ``points`` (m, 3) m and inward ``normals``
        (m, 3) (object frame; None: none); geoms are rebuilt only when ``key`` (hand, object,
        scale, task) changes, otherwise only moved."""
        if key != self._key:
            self._build(posed)
            self._key = key
        self.scene.remove_by_name("/grasp/contacts")
        pos, quat, opos, oquat = posed.state(state)
        for node, p, q in zip(self.nodes, pos, quat):
            if node is not None:
                node.position, node.wxyz = p, q
        frame = self.scene.add_frame("/grasp/contacts", show_axes=False, position=opos, wxyz=oquat,
                                     visible=self.visible["contacts"])
        self.contacts = frame
        points = np.asarray(points if points is not None else [], dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(normals if normals is not None else [], dtype=np.float64).reshape(-1, 3)
        r = max(0.002, 0.05 * posed.scene.objects.scale)
        for k, p in enumerate(points):
            self.scene.add_icosphere(f"/grasp/contacts/p{k}", radius=r, color=CONTACT_RGB, position=p)
        if len(normals) == len(points) and len(points):
            segs = np.stack([points - NORMAL_LENGTH_M * normals, points], axis=1)
            self.scene.add_arrows("/grasp/contacts/normals", segs, NORMAL_RGB, shaft_radius=0.0012,
                                  head_radius=0.003, head_length=0.006)

    def clear(self) -> None:
        """Remove every node of the drawn row."""
        self.scene.remove_by_name("/grasp")
        self.nodes, self.roles, self.contacts, self._key = [], [], None, None

    def set_visible(self, role: str, on: bool) -> None:
        """Show or hide one role: ``object``, ``hand``, ``collision`` or ``contacts``."""
        self.visible[role] = on
        if role == "contacts":
            if self.contacts is not None:
                self.contacts.visible = on
            return
        for node, r in zip(self.nodes, self.roles):
            if node is not None and r == role:
                node.visible = on
