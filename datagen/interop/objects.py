"""Objects between layouts: a processed object (``datagen.objects.layout``) out to a peer's
folder of convex pieces, and a peer's pieces in as a processed object that ``datagen eval`` and
``datagen render`` accept.

A peer object (DexGraspBench, BODex's processed objects) is a folder ``urdf/meshes/*.obj`` of
convex pieces in the object's own frame, scaled by a per-grasp ``obj_scale``;
``info/simplified.json`` holds ``mass``, ``density`` and ``scale`` (the peer derives the volume
as mass / (density * scale^3) to weigh the object 0.1 kg); ``mesh/simplified.obj`` is a
watertight surface for display.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import trimesh

from datagen._atomic import atomic_dir
from datagen.objects import layout

__all__ = ["IMPORT_CONFIG_HASH", "export_object", "import_object"]

IMPORT_CONFIG_HASH = "import"  # config_hash of an imported entry (not made by datagen's processing)


def export_object(entry: Path, out: Path) -> Path:
    """Write the processed object at ``entry`` (normalized units) as a peer object folder
    ``out``: pieces ``urdf/meshes/convex_piece_<i>.obj`` (normalized units, so the peer's
    ``obj_scale`` is our ``object_scale_m``), ``info/simplified.json`` and ``mesh/simplified.obj``,
    all or none (built in a temporary folder). Returns ``out``."""
    meta = json.loads((entry / layout.META).read_text())
    if meta.get("status") != "ok":
        raise ValueError(f"object {meta.get('object_id')!r} at {entry}: not a processed object (status "
                         f"{meta.get('status')!r})")
    volumes = [float(v) for v in meta["piece_volumes"]]
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_dir(out) as tmp:
        _write_peer_object(entry, tmp, meta, volumes)
    return out


def _write_peer_object(entry: Path, out: Path, meta: dict, volumes: list[float]) -> None:
    (out / "urdf" / "meshes").mkdir(parents=True, exist_ok=True)
    for i in range(len(volumes)):
        shutil.copyfile(entry / layout.PIECES_DIR / layout.PIECE.format(i=i),
                        out / "urdf" / "meshes" / f"convex_piece_{i}.obj")
    (out / "info").mkdir(exist_ok=True)
    info = {"scale": 1.0, "density": 1.0, "mass": float(sum(volumes)), "datagen_object_id": meta["object_id"]}
    (out / "info" / "simplified.json").write_text(json.dumps(info, indent=1))
    (out / "mesh").mkdir(exist_ok=True)
    surface = next((entry / n for n in (layout.SURFACE, layout.NORMALIZED) if (entry / n).is_file()), None)
    if surface is not None:
        shutil.copyfile(surface, out / "mesh" / "simplified.obj")
    else:  # all pieces in one mesh
        trimesh.util.concatenate([trimesh.load(p, force="mesh") for p in sorted((out / "urdf" / "meshes").iterdir())]
                                 ).export(out / "mesh" / "simplified.obj")


def import_object(folder: Path, object_id: str, out: Path) -> tuple[np.ndarray, float]:
    """Make a processed-object entry ``out`` (meta.json, coacd pieces, surface) from a peer
    object ``folder``. Pieces are normalized as datagen's are (centred at the bounding box of all
    pieces, half-diagonal 1). Returns (centre (3,), factor): normalized = (peer - centre) * factor,
    so a grasp at peer scale s lies at object_scale_m = s / factor. The entry is built in a
    temporary folder: ``out`` is the old entry or the complete new one."""
    pieces_dir = folder / "urdf" / "meshes"
    files = sorted(pieces_dir.glob("*.obj")) if pieces_dir.is_dir() else []
    if not files:
        raise FileNotFoundError(f"object {object_id!r}: no convex pieces {pieces_dir}/*.obj")
    meshes = [trimesh.load(p, force="mesh", process=False) for p in files]
    allv = np.concatenate([m.vertices for m in meshes])
    lo, hi = allv.min(0), allv.max(0)
    centre, factor = (lo + hi) / 2, 1.0 / max(float(np.linalg.norm(hi - lo)) / 2, 1e-12)
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_dir(out) as tmp:
        _write_entry(tmp, folder, object_id, meshes, files, centre, factor)
    return centre, factor


def _write_entry(out: Path, folder: Path, object_id: str, meshes: list, files: list[Path], centre: np.ndarray,
                 factor: float) -> None:
    (out / layout.PIECES_DIR).mkdir(parents=True)
    volumes, digest = [], hashlib.sha256()
    for i, (m, p) in enumerate(zip(meshes, files)):
        digest.update(p.read_bytes())
        n = trimesh.Trimesh((m.vertices - centre) * factor, m.faces, process=False)
        hull = n if n.is_volume else n.convex_hull  # pieces are convex: their hull is the piece
        volumes.append(float(abs(hull.volume)))
        n.export(out / layout.PIECES_DIR / layout.PIECE.format(i=i))
    surface = folder / "mesh" / "simplified.obj"
    if surface.is_file():
        s = trimesh.load(surface, force="mesh", process=False)
        trimesh.Trimesh((s.vertices - centre) * factor, s.faces, process=False).export(out / layout.SURFACE)
    meta = {"meta_version": layout.META_VERSION, "object_id": object_id, "status": "ok",
            "mesh_sha256": digest.hexdigest(), "config_hash": IMPORT_CONFIG_HASH,
            "centre": [float(c) for c in centre], "factor": factor, "piece_volumes": volumes,
            "surface_origin": "imported" if surface.is_file() else "", "imported_from": str(folder)}
    (out / layout.META).write_text(json.dumps(meta, indent=1))
