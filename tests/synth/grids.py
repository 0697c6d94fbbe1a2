"""Small grasp targets with SDF grids, shared by the grid-query tests (stacked, penetration)."""

from __future__ import annotations

import numpy as np
import trimesh

from datagen.synth import GraspTarget


def grid_targets(resolutions=(24, 24, 24)) -> list[GraspTarget]:
    """A cylinder at 7 cm, a box at 8 cm and the cylinder at 10 cm, with grids of ``resolutions``."""
    cyl = trimesh.creation.cylinder(radius=0.35, height=1.0, sections=32)
    box = trimesh.creation.box((1.0, 0.7, 0.5))
    out = []
    for mesh, scale, res in zip((cyl, box, cyl), (0.07, 0.08, 0.1), resolutions):
        mesh = mesh.copy()
        mesh.apply_scale(1 / np.linalg.norm(0.5 * mesh.extents))
        out.append(GraspTarget.from_mesh(mesh, scale, f"t{scale}", grid_resolution=res))
    return out
