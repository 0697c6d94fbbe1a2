"""Object sources: each enumerates (object id, raw mesh) pairs under a source URI.

Source URIs (the ``--source`` argument and the manifest's ``source`` field):

- ``procedural`` or ``procedural:SEED``: the built-in generator (``procedural.py``); an object's
  path is its index, e.g. ``"17"``.
- ``dexgraspnet:ROOT``: DexGraspNet's meshdata layout, ``ROOT/<code>/coacd/decomposed.obj``; the
  path is ``<code>/coacd/decomposed.obj``; its ``coacd_convex_piece_<i>.obj`` are reused.
- ``dir:ROOT``: every obj/stl/ply/off/glb entry under ROOT (recursive, sorted); the path is the
  entry's path relative to ROOT. Entries that are not regular files inside ROOT (a directory
  named ``x.obj``, a device, a looping or escaping symlink) are still enumerated, so the manifest
  builder can record why each one was rejected. The id is the sanitised path (``_id_from_path``);
  an id longer than 200 characters, or one that another path of the source already sanitises to,
  gets a hash of its path as suffix, so ids are unique and valid manifest ids.
- ``pybullet``: pybullet_data/random_urdfs/<n>/<n>.obj (needs the optional pybullet package).
- ``pkg:MODULE[/SUBDIR]``: the files of an installed Python package (e.g.
  ``pkg:pybullet_data``, ``pkg:metaworld/assets/objects/meshes``), like ``dir:`` but the root is
  looked up where the package is installed, so a manifest of such objects works on any machine.
- ``tasks``: the ten task-benchmark objects (``task_objects.py``); the path is the object name,
  e.g. ``"knob3"``, the id ``task-<name>``. Their convex parts are exact (no CoACD) and a built
  manifest gives each its own scale (its joint anchor is in metres at that scale).

Paths are always relative to the source root; ``resolve`` rejects any that escapes it.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from datagen import _bounded

from . import procedural, task_objects
from .config import MAX_MESH_BYTES
from .errors import ManifestError, MeshProcessingError, Reason, SourceError
from .mesh_ops import MESH_EXTENSIONS

__all__ = ["ObjectRef", "iter_source", "resolve", "canonical_source"]

_PIECE = re.compile(r"coacd_convex_piece_(\d+)\.obj$")


@dataclass(frozen=True)
class ObjectRef:
    """One object of a source: enough to read its raw mesh (and any existing convex pieces)."""

    object_id: str
    source: str          # canonical source URI, e.g. "dir:/abs/root"
    path: str            # relative to the source root (procedural: the index)
    file_type: str       # obj, stl, ply, off or glb
    family: str = ""     # procedural family, "" for file sources

    @property
    def file(self) -> Path | None:
        """Absolute mesh file, or None for generated objects."""
        root = _root(self.source)
        return None if root is None else root / self.path

    def read_bytes(self, max_bytes: int = MAX_MESH_BYTES) -> bytes:
        """The raw mesh bytes (a file of at most ``max_bytes``); MeshProcessingError naming the
        file: ``missing_file`` if it is gone, ``not_a_regular_file`` for a directory, device, FIFO
        or socket (refused before reading), ``file_too_large`` over ``max_bytes``."""
        if self.source == "tasks":
            return task_objects.obj_bytes(self.path)
        if self.file is None:
            seed, index = _procedural_seed(self.source), int(self.path)
            return procedural.generate(seed, index).obj_bytes
        try:
            return _bounded.read_bytes(self.file, max_bytes, "mesh")
        except _bounded.InputError as exc:
            raise self._error(exc) from None

    def sha256(self, max_bytes: int = MAX_MESH_BYTES) -> str:
        """sha256 (hex) of the raw mesh bytes, a file streamed in chunks (errors as `read_bytes`)."""
        if self.file is None:
            return hashlib.sha256(self.read_bytes()).hexdigest()
        try:
            return _bounded.sha256_file(self.file, max_bytes, "mesh")[0]
        except _bounded.InputError as exc:
            raise self._error(exc) from None

    def _error(self, exc) -> MeshProcessingError:
        reason = {_bounded.NOT_FOUND: Reason.MISSING_FILE, _bounded.TOO_LARGE: Reason.FILE_TOO_LARGE}.get(
            exc.reason, Reason.NOT_A_FILE)
        if reason is Reason.MISSING_FILE:
            return MeshProcessingError(reason, self.object_id, f"mesh file {self.file} does not exist")
        remedy = " (raise ProcessConfig.max_mesh_bytes, the job's process: {max_mesh_bytes: N}, to allow it)" \
            if reason is Reason.FILE_TOO_LARGE else ""
        detail = exc.detail.removeprefix("the mesh ")
        where = f"{self.file} " if detail != exc.detail else f"{self.file}: "
        return MeshProcessingError(reason, self.object_id, where + detail + remedy)

    def piece_files(self) -> list[Path]:
        """Existing CoACD pieces next to a DexGraspNet decomposed.obj, in index order."""
        if not self.source.startswith("dexgraspnet:") or self.file is None:
            return []
        found = [(int(m.group(1)), p) for p in self.file.parent.glob("coacd_convex_piece_*.obj")
                 if (m := _PIECE.search(p.name))]
        return [p for _, p in sorted(found)]


def canonical_source(uri: str) -> str:
    """Normalize a source URI (absolute roots, explicit procedural seed)."""
    kind, _, arg = uri.partition(":")
    if kind == "procedural":
        return f"procedural:{_procedural_seed(uri)}"
    if kind in ("dir", "dexgraspnet"):
        if not arg:
            raise SourceError(Reason.UNKNOWN_SOURCE, uri, f"{kind}: needs a folder, e.g. {kind}:/data")
        return f"{kind}:{Path(arg).expanduser().resolve()}"
    if kind == "pybullet":
        return f"dir:{_pybullet_root()}"
    if kind == "tasks" and not arg:
        return "tasks"
    if kind == "pkg" and arg:
        module, _, sub = arg.strip("/").partition("/")
        return f"pkg:{module}" + (f"/{Path(sub).as_posix()}" if sub else "")
    raise SourceError(Reason.UNKNOWN_SOURCE, uri,
                      "use procedural[:SEED], dexgraspnet:PATH, dir:PATH, pkg:MODULE[/SUBDIR], pybullet or tasks")


def _procedural_seed(uri: str) -> int:
    arg = uri.partition(":")[2]
    if not arg:
        return 0
    if not arg.isdigit():
        raise SourceError(Reason.UNKNOWN_SOURCE, uri, "procedural seed must be an int >= 0")
    return int(arg)


def _root(source: str) -> Path | None:
    kind, _, arg = source.partition(":")
    if kind == "pkg":
        return _package_root(arg)
    return None if kind in ("procedural", "tasks") else Path(arg)


def _package_root(arg: str) -> Path:
    """``MODULE[/SUBDIR]`` -> the folder of the installed package MODULE (not imported) / SUBDIR."""
    import importlib.util

    module, _, sub = arg.partition("/")
    spec = importlib.util.find_spec(module) if module.isidentifier() else None
    if spec is None or not spec.submodule_search_locations:
        raise SourceError(Reason.UNKNOWN_SOURCE, f"pkg:{arg}",
                          f"Python package {module!r} is not installed (e.g. `make real-objects`)")
    return Path(list(spec.submodule_search_locations)[0]) / sub


def _pybullet_root() -> Path:
    try:
        import pybullet_data
    except ImportError as exc:
        raise SourceError(Reason.UNKNOWN_SOURCE, "pybullet",
                          "pybullet is not installed (pip install pybullet)") from exc
    return Path(pybullet_data.getDataPath()) / "random_urdfs"


MAX_ID_LEN = 200  # the manifest's id limit


def _id_from_path(rel: str) -> str:
    """'sub dir/box.obj' -> 'sub_dir__box.obj' (the extension stays: box.obj and box.stl differ)."""
    parts = [re.sub(r"[^A-Za-z0-9._-]+", "_", p) for p in rel.split("/")]
    return "__".join(parts).lstrip("._-") or "object"


def _with_path_hash(object_id: str, rel: str) -> str:
    """``object_id`` cut to fit MAX_ID_LEN with ``-<12 hex of sha256(rel)>`` appended."""
    tag = hashlib.sha256(rel.encode()).hexdigest()[:12]
    return f"{object_id[:MAX_ID_LEN - 13]}-{tag}"


def unique_ids(rels: list[str]) -> list[str]:
    """Ids of the sorted relative paths ``rels``: ``_id_from_path``, except that an id over
    MAX_ID_LEN characters, or one an earlier path already has, gets a path hash as suffix
    (deterministic: the same folder gives the same ids)."""
    out, seen = [], set()
    for rel in rels:
        oid = _id_from_path(rel)
        if len(oid) > MAX_ID_LEN or oid in seen:
            oid = _with_path_hash(oid, rel)
        seen.add(oid)
        out.append(oid)
    return out


def iter_source(uri: str, count: int | None = None) -> Iterator[ObjectRef]:
    """Enumerate up to ``count`` objects of a source (all file objects if None)."""
    source = canonical_source(uri)
    kind, _, arg = source.partition(":")
    if kind == "procedural":
        if count is None:
            raise SourceError(Reason.UNKNOWN_SOURCE, uri, "the procedural source needs a count")
        seed = int(arg)
        for i in range(count):
            yield ObjectRef(procedural.object_id(seed, i), source, str(i), "obj",
                            procedural.family_of(seed, i))
        return
    if kind == "tasks":
        for name in task_objects.TASK_OBJECTS[:count]:
            yield ObjectRef(task_objects.object_id(name), source, name, "obj", name)
        return
    root = _root(source)
    if not root.is_dir():
        raise SourceError(Reason.UNKNOWN_SOURCE, uri, f"source folder {root} does not exist")
    if kind == "dexgraspnet":
        rels = sorted(p.relative_to(root).as_posix() for p in root.glob("*/coacd/decomposed.obj"))
        ids = [rel.split("/", 1)[0] for rel in rels]  # the object code
    else:
        # every entry with a mesh suffix, whatever it is (rglob does not follow directory links):
        # the manifest builder rejects the unusable ones with a reason instead of losing them
        rels = sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                      if p.suffix.lower().lstrip(".") in MESH_EXTENSIONS and not p.name.endswith("_coll.obj"))
        ids = unique_ids(rels)
    for n, (rel, oid) in enumerate(zip(rels, ids)):
        if count is not None and n >= count:
            return
        yield ObjectRef(oid, source, rel, Path(rel).suffix.lower().lstrip("."))


def resolve(source: str, path: str, object_id: str, family: str = "") -> ObjectRef:
    """The ObjectRef of a manifest line; ManifestError(path_escapes_root) for a path that
    leaves the source root (absolute, '..', or a symlink pointing out)."""
    source = canonical_source(source)
    root = _root(source)
    if source == "tasks":
        if path not in task_objects.TASK_OBJECTS:
            raise ManifestError(Reason.SCHEMA, object_id, f"unknown task object {path!r}; known: "
                                f"{list(task_objects.TASK_OBJECTS)}")
        return ObjectRef(object_id, source, path, "obj", family)
    if root is None:
        if not path.isdigit():
            raise ManifestError(Reason.SCHEMA, object_id, f"procedural path must be an index, got {path!r}")
        return ObjectRef(object_id, source, path, "obj", family)
    try:
        target = (root / path).resolve()
    except (RuntimeError, OSError) as exc:  # a symlink loop
        raise ManifestError(Reason.NOT_A_FILE, object_id, f"path {path!r} cannot be resolved: {exc}") from None
    if Path(path).is_absolute() or not target.is_relative_to(root.resolve()):
        raise ManifestError(Reason.PATH_ESCAPES_ROOT, object_id,
                            f"path {path!r} resolves outside the source root {root}")
    return ObjectRef(object_id, source, path, Path(path).suffix.lower().lstrip("."), family)
