"""Per-object pipeline: load -> validate -> repair -> normalize -> CoACD -> surface -> MJCF.

Idempotent and cached: ``process_object`` returns the cache entry for (``object_key``, config
hash) if it exists, else builds it atomically (``cache.atomic_entry``). The key is the raw mesh
sha256 together with everything else that decides the result: the file type the bytes are
parsed as, and existing DexGraspNet pieces or a task object's builder. Failures are returned as
``ProcessedObject(status="failed", reason=...)``; deterministic ones (anything decided by the
mesh bytes) are cached like successes, a missing file is not. A cache entry may have been made
for another object with the same bytes: what is returned always carries the caller's object id
(and a failure message naming it).
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from datagen import _bounded

from . import layout, task_objects
from .cache import atomic_entry, cache_root, entry_dir
from .coacd_step import decompose, pieces_from_meshes
from .config import MAX_MESH_BYTES, PROCESS_VERSION, ProcessConfig
from .errors import MeshProcessingError, Reason
from .mesh_ops import load_mesh_bytes, normalize, obj_bytes, repair, validate
from .mjcf import check_mjcf, object_mjcf
from .sources import ObjectRef
from .surface import watertight_surface

__all__ = ["ProcessedObject", "process_object", "load_processed", "object_key", "as_object", "read_meta"]


@dataclass(frozen=True)
class ProcessedObject:
    """A processed object (or a failure). Paths are absolute; geometry in normalized units.

    ``centre`` (3,) and ``factor`` map raw to normalized: normalized = (raw - centre) * factor.
    At manifest scale s (metres) a normalized point x is at s * x metres in the object frame.
    """

    object_id: str
    status: str                      # "ok" or "failed"
    reason: str = ""                 # a Reason value when failed
    message: str = ""
    entry: Path | None = None
    mesh_sha256: str = ""
    config_hash: str = ""
    cache_hit: bool = False
    centre: tuple = (0.0, 0.0, 0.0)
    factor: float = 1.0
    piece_volumes: tuple = ()
    surface_origin: str = ""
    timings: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def piece_paths(self) -> list[Path]:
        d = self.entry / layout.PIECES_DIR
        return [d / layout.PIECE.format(i=i) for i in range(len(self.piece_volumes))]

    @property
    def surface_path(self) -> Path:
        return self.entry / layout.SURFACE

    @property
    def mjcf_path(self) -> Path:
        return self.entry / layout.MJCF

    def mjcf(self, scale: float) -> str:
        """MJCF text of this object at ``scale`` metres, meshdir absolute (usable anywhere)."""
        return object_mjcf([p.name for p in self.piece_paths], list(self.piece_volumes), scale,
                           meshdir=str(self.entry / layout.PIECES_DIR),
                           total_mass_kg=self.meta["config"]["total_mass_kg"],
                           condim=self.meta["config"]["geom_condim"],
                           friction=tuple(self.meta["config"]["geom_friction"]))

    @property
    def meta(self) -> dict:
        """The entry's meta.json (config, normalization, pieces, timings, versions)."""
        return read_meta(self.entry)


def read_meta(entry: Path) -> dict:
    """A processed object's meta.json; ValueError (`datagen._bounded.InputError`) naming the file
    when it is missing, unreadable or not JSON, with the remedy: remove the entry, which is then
    rebuilt."""
    try:
        return _bounded.read_json(Path(entry) / layout.META, "processed object's meta.json")
    except _bounded.InputError as exc:
        raise _bounded.InputError(exc.path, exc.reason, exc.detail,
                                  f"remove {entry} and rerun: the object is processed again") from None


def load_processed(entry: Path, cache_hit: bool = True) -> ProcessedObject:
    """Read a cache entry's meta.json (raises ValueError naming it, also on a wrong meta version)."""
    meta = read_meta(entry)
    if meta.get("meta_version") != layout.META_VERSION:
        raise ValueError(f"{entry}: meta_version {meta.get('meta_version')} != {layout.META_VERSION}")
    return ProcessedObject(
        object_id=meta["object_id"], status=meta["status"], reason=meta.get("reason", ""),
        message=meta.get("message", ""), entry=Path(entry), mesh_sha256=meta["mesh_sha256"],
        config_hash=meta["config_hash"], cache_hit=cache_hit,
        centre=tuple(meta.get("centre", (0, 0, 0))), factor=meta.get("factor", 1.0),
        piece_volumes=tuple(meta.get("piece_volumes", ())),
        surface_origin=meta.get("surface_origin", ""), timings=meta.get("timings", {}))


def object_key(ref: ObjectRef, mesh_sha256: str) -> str:
    """Cache key (64 hex) of an object whose raw bytes hash to ``mesh_sha256``: the same bytes
    read as another file type, or with other existing pieces, are another entry."""
    parts = [mesh_sha256, ref.file_type]
    if ref.source == "tasks":  # pieces come from the task object's builder, not from CoACD
        parts.append(f"tasks:{ref.path}")
    parts += [_bounded.sha256_file(p, MAX_MESH_BYTES, "convex piece")[0] for p in ref.piece_files()]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()


def as_object(p: ProcessedObject, ref: ObjectRef) -> ProcessedObject:
    """``p`` (maybe a cache entry made for another object with the same bytes) labelled with
    ``ref``'s object id, its failure message naming ``ref``."""
    if p.object_id == ref.object_id:
        return p
    message = p.message
    if not p.ok:
        message = f"{ref.object_id}: {p.reason}: {p.meta.get('detail', p.message)}"
    return replace(p, object_id=ref.object_id, message=message)


def _build(ref: ObjectRef, raw: bytes, cfg: ProcessConfig, tmp: Path, meta: dict) -> None:
    """Fill ``tmp`` with a complete entry; raises MeshProcessingError on a bad mesh."""
    t, thing = meta["timings"], ref.object_id

    def lap(name: str, t0: float) -> float:
        now = time.perf_counter()
        t[name] = round(now - t0, 4)
        return now

    t0 = time.perf_counter()
    mesh = load_mesh_bytes(raw, ref.file_type, thing)
    t0 = lap("load", t0)
    validate(mesh, cfg, thing)
    t0 = lap("validate", t0)
    mesh = repair(mesh)
    validate(mesh, cfg, thing)
    t0 = lap("repair", t0)
    mesh, centre, factor = normalize(mesh)
    (tmp / layout.NORMALIZED).write_bytes(obj_bytes(mesh.vertices, mesh.faces, thing))
    t0 = lap("normalize", t0)
    existing = ref.piece_files()
    if ref.source == "tasks":  # exact convex parts of a task object, in its (centred) raw frame
        parts = [((np.asarray(v) - centre) * factor, f) for v, f in task_objects.build(ref.path).parts]
        pieces, meta["pieces_origin"] = pieces_from_meshes(parts, cfg, thing), "builder"
    elif existing:  # DexGraspNet pieces: same normalization as their decomposed.obj
        parts = []
        for p in existing:
            m = load_mesh_bytes(_bounded.read_bytes(p, MAX_MESH_BYTES, "convex piece"), "obj", f"{thing}/{p.name}")
            parts.append(((np.asarray(m.vertices) - centre) * factor, m.faces))
        pieces, meta["pieces_origin"] = pieces_from_meshes(parts, cfg, thing), "reused"
    else:
        pieces, meta["pieces_origin"] = decompose(mesh.vertices, mesh.faces, cfg, thing), "coacd"
    t0 = lap("coacd", t0)
    (tmp / layout.PIECES_DIR).mkdir()
    allv, allf, off = [], [], 0
    for i, p in enumerate(pieces):
        (tmp / layout.PIECES_DIR / layout.PIECE.format(i=i)).write_bytes(obj_bytes(p.vertices, p.faces))
        allv.append(p.vertices)
        allf.append(p.faces + off)
        off += len(p.vertices)
    (tmp / layout.PIECES_DIR / layout.DECOMPOSED).write_bytes(
        obj_bytes(np.concatenate(allv), np.concatenate(allf)))
    sv, sf, origin = watertight_surface(mesh, pieces, cfg, thing)
    (tmp / layout.SURFACE).write_bytes(obj_bytes(sv, sf))
    t0 = lap("surface", t0)
    names, vols = [layout.PIECE.format(i=i) for i in range(len(pieces))], [p.volume for p in pieces]
    for scale, fname in ((1.0, layout.MJCF), (cfg.mjcf_check_scale, "check.xml")):
        (tmp / fname).write_text(object_mjcf(names, vols, scale, meshdir=layout.PIECES_DIR,
                                             total_mass_kg=cfg.total_mass_kg, condim=cfg.geom_condim,
                                             friction=cfg.geom_friction))
    try:
        mass = check_mjcf(tmp / "check.xml")
    except ValueError as exc:
        raise MeshProcessingError(Reason.MJCF_FAILED, thing, str(exc)) from exc
    finally:
        (tmp / "check.xml").unlink()
    lap("mjcf", t0)
    meta.update(status="ok", centre=[float(c) for c in centre], factor=float(factor),
                piece_volumes=vols, surface_origin=origin, surface_faces=int(len(sf)),
                mass_kg=mass)


def process_object(ref: ObjectRef, cfg: ProcessConfig | None = None,
                   root: str | Path | None = None,
                   expected_sha256: str | None = None) -> ProcessedObject:
    """Process one object (or return its cache entry). Never raises for a bad mesh.

    ``expected_sha256`` (the manifest's) turns a changed file into a sha256_mismatch failure.
    """
    cfg = cfg or ProcessConfig()
    try:
        raw = ref.read_bytes(cfg.max_mesh_bytes)
    except MeshProcessingError as exc:
        return ProcessedObject(ref.object_id, "failed", exc.reason.value, str(exc))
    sha, chash = hashlib.sha256(raw).hexdigest(), cfg.hash()
    if expected_sha256 is not None and sha != expected_sha256:
        return ProcessedObject(ref.object_id, "failed", Reason.SHA_MISMATCH.value,
                               f"{ref.object_id}: {Reason.SHA_MISMATCH.value}: file sha256 {sha[:12]}... != manifest "
                               f"{expected_sha256[:12]}...; the file changed since the manifest was built: rebuild it",
                               mesh_sha256=expected_sha256)
    try:
        key = object_key(ref, sha)
    except (OSError, ValueError, MeshProcessingError) as exc:  # ValueError: datagen._bounded.InputError
        return ProcessedObject(ref.object_id, "failed", Reason.MISSING_FILE.value,
                               f"{ref.object_id}: {Reason.MISSING_FILE.value}: its pieces cannot be read: {exc}")
    final = entry_dir(cache_root(root), key, chash)
    if (final / layout.META).is_file():
        return as_object(load_processed(final, cache_hit=True), ref)
    meta = {"meta_version": layout.META_VERSION, "process_version": PROCESS_VERSION,
            "object_id": ref.object_id, "source": ref.source, "path": ref.path,
            "mesh_sha256": sha, "config_hash": chash, "config": cfg.to_dict(), "timings": {}}
    with atomic_entry(final) as tmp:
        try:
            _build(ref, raw, cfg, tmp, meta)
        except MeshProcessingError as exc:
            for p in sorted(tmp.iterdir(), reverse=True):  # a failed entry holds only meta.json
                if p.is_dir():
                    for q in p.iterdir():
                        q.unlink()
                    p.rmdir()
                else:
                    p.unlink()
            meta.update(status="failed", reason=exc.reason.value, message=str(exc), detail=exc.detail)
        (tmp / layout.META).write_text(json.dumps(meta, indent=1, sort_keys=True))
    return as_object(load_processed(final, cache_hit=False), ref)
