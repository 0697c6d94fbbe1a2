"""Mesh loading, validation, repair and normalization (NumPy/trimesh, no torch).

Frames and units: raw meshes are in the units of their file. ``normalize`` returns the mesh in
*normalized object units*: centred at its bounding-box centre, scaled so the bounding-box
half-diagonal is 1. ``raw = normalized / factor + centre``.
"""

from __future__ import annotations

import io
import warnings

import numpy as np
import trimesh

from .config import ProcessConfig
from .errors import MeshProcessingError, Reason

__all__ = ["MESH_EXTENSIONS", "load_mesh_bytes", "validate", "repair", "normalize", "obj_bytes"]

MESH_EXTENSIONS = ("obj", "stl", "ply", "off", "glb")


def load_mesh_bytes(data: bytes, file_type: str, thing: str) -> trimesh.Trimesh:
    """Parse ``data`` (a file of type ``file_type``) into one triangle mesh, without processing.

    Scenes (glb, multi-object obj) are concatenated with their transforms applied.
    """
    file_type = file_type.lower().lstrip(".")
    if file_type not in MESH_EXTENSIONS:
        raise MeshProcessingError(Reason.UNREADABLE_MESH, thing,
                                  f"unsupported file type {file_type!r} (use one of {MESH_EXTENSIONS})")
    if not data.strip():
        raise MeshProcessingError(Reason.EMPTY_MESH, thing, "the file is empty")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loaded = trimesh.load(io.BytesIO(data), file_type=file_type, process=False)
    except Exception as exc:  # every parser error means the same thing here
        raise MeshProcessingError(Reason.UNREADABLE_MESH, thing,
                                  f"{file_type} parser failed ({type(exc).__name__}: {exc})") from exc
    if isinstance(loaded, trimesh.PointCloud):
        raise MeshProcessingError(Reason.EMPTY_MESH, thing,
                                  f"{len(loaded.vertices)} vertices and no faces (a point cloud)")
    if isinstance(loaded, trimesh.Scene):
        meshes = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        loaded = trimesh.util.concatenate(meshes) if meshes else trimesh.Trimesh()
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshProcessingError(Reason.UNREADABLE_MESH, thing,
                                  f"file holds no triangle mesh (got {type(loaded).__name__})")
    if len(loaded.vertices) == 0 and len(loaded.faces) == 0:
        raise MeshProcessingError(Reason.UNREADABLE_MESH, thing,
                                  f"the {file_type} parser found no vertices in {len(data)} bytes")
    return loaded


def validate(mesh: trimesh.Trimesh, cfg: ProcessConfig, thing: str) -> None:
    """Reject empty, non-finite, oversized, huge-coordinate and zero-volume meshes."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces)
    if len(v) == 0 or len(f) == 0:
        raise MeshProcessingError(Reason.EMPTY_MESH, thing, f"{len(v)} vertices, {len(f)} faces")
    if not np.isfinite(v).all():
        bad = int((~np.isfinite(v)).any(axis=1).sum())
        raise MeshProcessingError(Reason.NON_FINITE, thing, f"{bad} vertices have NaN/inf coordinates")
    if len(f) > cfg.max_faces:
        raise MeshProcessingError(Reason.TOO_LARGE, thing,
                                  f"{len(f)} faces > max_faces={cfg.max_faces}; decimate it first")
    used = v[np.unique(f)] if f.size else v
    big = float(np.abs(used).max())
    if big > cfg.max_abs_coordinate_raw:
        raise MeshProcessingError(Reason.HUGE_COORDINATES, thing,
                                  f"max |coordinate| {big:.3g} > {cfg.max_abs_coordinate_raw:.3g}")
    diag = float(np.linalg.norm(used.max(0) - used.min(0)))
    if diag <= 0:
        raise MeshProcessingError(Reason.DEGENERATE, thing, "all vertices coincide (zero extent)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # flat hulls warn while computing their zero volume
            hull = trimesh.convex.convex_hull(used / diag, qhull_options="QbB Pp")
            hull_volume = float(abs(hull.volume))
    except Exception:  # qhull fails on flat or collinear input: that is zero volume
        hull_volume = 0.0
    if hull_volume <= cfg.min_volume_fraction:
        raise MeshProcessingError(Reason.DEGENERATE, thing,
                                  f"zero volume (hull volume / diagonal^3 = {hull_volume:.2e})")


def repair(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Merge duplicate vertices, drop degenerate/duplicate faces, orient, fill small holes."""
    m = trimesh.Trimesh(vertices=np.asarray(mesh.vertices, np.float64),
                        faces=np.asarray(mesh.faces, np.int64), process=False)
    m.merge_vertices()
    m.update_faces(m.nondegenerate_faces())
    m.update_faces(m.unique_faces())
    m.remove_unreferenced_vertices()
    trimesh.repair.fix_winding(m)
    if m.is_watertight and m.volume < 0:
        m.invert()
    if not m.is_watertight:
        trimesh.repair.fill_holes(m)
    return m


def normalize(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, np.ndarray, float]:
    """Centre at the bounding-box centre and scale to half-diagonal 1.

    Returns (normalized mesh, centre (3,) raw units, factor) with normalized = (raw - centre) * factor.
    """
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2.0
    factor = 2.0 / float(np.linalg.norm(hi - lo))
    v = (np.asarray(mesh.vertices) - centre) * factor
    return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False), centre, factor


def obj_bytes(vertices: np.ndarray, faces: np.ndarray, header: str = "") -> bytes:
    """Deterministic OBJ text: '%.8f' vertices, 1-based triangle faces."""
    lines = [f"# {header}"] if header else []
    lines += ["v %.8f %.8f %.8f" % tuple(p) for p in np.asarray(vertices, np.float64).tolist()]
    lines += ["f %d %d %d" % tuple(t) for t in (np.asarray(faces, np.int64) + 1).tolist()]
    return ("\n".join(lines) + "\n").encode("ascii")
