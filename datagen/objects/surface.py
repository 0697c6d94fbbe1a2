"""The simplified watertight surface (normalized units), built with manifold3d.

If the repaired mesh is closed, its connected components are turned into manifolds and
unioned (overlapping parts, common in scanned/CAD soups, become one solid), then simplified
(every surface point moves by less than the tolerance). Otherwise the union of the convex
pieces is used: always watertight, but concavities narrower than CoACD's threshold are filled.
This is the same centring and scaling convention as BODex's MeshProcess (bbox centre, half
diagonal 1).
"""

from __future__ import annotations

import manifold3d as mf
import numpy as np
import trimesh

from .coacd_step import ConvexPiece
from .config import ProcessConfig
from .errors import MeshProcessingError, Reason

__all__ = ["watertight_surface"]


def _as_manifold(vertices: np.ndarray, faces: np.ndarray) -> mf.Manifold | None:
    mesh = mf.Mesh(vert_properties=np.asarray(vertices, np.float32),
                   tri_verts=np.asarray(faces, np.uint32))
    solid = mf.Manifold(mesh)
    ok = solid.status() == mf.Error.NoError and not solid.is_empty()
    return solid if ok else None


def watertight_surface(mesh: trimesh.Trimesh, pieces: list[ConvexPiece], cfg: ProcessConfig,
                       thing: str) -> tuple[np.ndarray, np.ndarray, str]:
    """Return (vertices (n, 3), faces (f, 3), origin) with origin 'mesh' or 'pieces_union'."""
    solid, origin = None, "mesh"
    if mesh.is_watertight and mesh.is_winding_consistent:
        parts = [_as_manifold(c.vertices, c.faces) for c in mesh.split(only_watertight=False)]
        if parts and all(p is not None for p in parts):
            solid = parts[0] if len(parts) == 1 else mf.Manifold.batch_boolean(parts, mf.OpType.Add)
    if solid is None:
        origin = "pieces_union"
        hulls = [mf.Manifold.hull_points(np.asarray(p.vertices, np.float64)) for p in pieces]
        solid = mf.Manifold.batch_boolean(hulls, mf.OpType.Add)
    tol = cfg.surface_tolerance
    for _ in range(12):
        simple = solid.simplify(tol)
        if simple.num_tri() <= cfg.surface_max_faces:
            break
        tol *= 2.0
    out = simple.to_mesh()
    v = np.asarray(out.vert_properties, np.float64)[:, :3]
    f = np.asarray(out.tri_verts, np.int64)
    check = trimesh.Trimesh(v, f, process=False)
    if len(f) == 0 or not check.is_watertight or check.volume <= 0:
        raise MeshProcessingError(Reason.SURFACE_FAILED, thing,
                                  f"simplified surface ({origin}) is empty or not watertight")
    return v, f, origin
