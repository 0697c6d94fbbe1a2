"""Object manifests: one JSON object per line, validated on load.

Line schema (all fields required, no others)::

    {"id": str, "source": str (canonical source URI), "path": str (relative to the source root;
     procedural: the index), "family": str ("" for files), "sha256": str (64 hex, raw mesh bytes),
     "scales": [float | "native", ...], "split": "train" | "test"}

A scale is the object's size: metres per normalized unit (objects are normalized so that their
bounding-box diagonal is 2, so a scale s makes that diagonal 2 s metres). ``"native"`` keeps the
mesh's own size, its coordinates read as metres: the scale becomes half the raw bounding-box
diagonal once the object is processed (`resolve_scales`). A lemon stays a lemon and a bowl a bowl.

The split is a function of the id alone (``split_of``), so it is stable when objects are added.
"""

from __future__ import annotations

import hashlib
import json
import logging
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterable

from datagen import _bounded
from datagen._atomic import atomic_write_text

from .config import MAX_MESH_BYTES
from .errors import ManifestError, ObjectError, Reason, SourceError
from . import task_objects
from .sources import ObjectRef, canonical_source, iter_source, resolve

log = logging.getLogger(__name__)

__all__ = ["DEFAULT_SCALES", "NATIVE", "ManifestEntry", "Rejected", "split_of", "build_manifest", "write_manifest",
           "load_manifest", "resolve_scales"]

DEFAULT_SCALES = (0.06, 0.08, 0.10, 0.12)
NATIVE = "native"  #: the scale that keeps a mesh's own size (coordinates in metres)
NATIVE_DIAGONAL_M = (0.01, 2.0)  #: a native bounding-box diagonal outside this is not an object in metres


def _scale_ok(s) -> bool:
    return s == NATIVE or (isinstance(s, (int, float)) and not isinstance(s, bool) and 0 < s < 10)


def _scale_value(s):
    return s if s == NATIVE else float(s)


def resolve_scales(scales: Iterable, factor: float, object_id: str) -> tuple[float, ...]:
    """Manifest ``scales`` in metres per normalized unit, ``"native"`` replaced by the object's own
    size ``1 / factor`` (``factor``: the processed object's raw-to-normalized factor; see
    `datagen.objects.ProcessedObject`). Raises `ManifestError` (reason ``native_size_out_of_range``)
    naming the object when its native bounding-box diagonal is outside `NATIVE_DIAGONAL_M`."""
    out = []
    for s in scales:
        if s == NATIVE:
            diagonal = 2.0 / float(factor)
            lo, hi = NATIVE_DIAGONAL_M
            if not lo <= diagonal <= hi:
                raise ManifestError(Reason.NATIVE_SIZE, object_id,
                                    f"scale 'native' reads the mesh's coordinates as metres, but its bounding-box "
                                    f"diagonal is {diagonal:.4g} of its units, outside [{lo}, {hi}] m (a mesh in "
                                    f"millimetres or normalized?); give this object numeric scales (metres)")
            s = 1.0 / float(factor)
        if float(s) not in out:
            out.append(float(s))
    return tuple(out)
_FIELDS = {"id": str, "source": str, "path": str, "family": str, "sha256": str, "scales": list,
           "split": str}
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,199}$")
_SHA = re.compile(r"^[0-9a-f]{64}$")


@dataclass(frozen=True)
class ManifestEntry:
    """One object of a manifest (see the module docstring for the fields)."""

    id: str
    source: str
    path: str
    family: str
    sha256: str
    scales: tuple
    split: str

    @classmethod
    def of_ref(cls, ref: ObjectRef, scales: tuple = (), split: str = "train",
               max_bytes: int = MAX_MESH_BYTES) -> "ManifestEntry":
        """The entry of ``ref`` with the sha256 of its bytes as they are now (streamed once here;
        a file over ``max_bytes`` is a ``file_too_large`` MeshProcessingError)."""
        return cls(ref.object_id, ref.source, ref.path, ref.family, ref.sha256(max_bytes), tuple(scales), split)

    def ref(self) -> ObjectRef:
        """The ObjectRef to read this object (the path is checked against the source root)."""
        return resolve(self.source, self.path, self.id, self.family)

    def to_json(self) -> str:
        d = asdict(self)
        d["scales"] = list(self.scales)
        return json.dumps(d, sort_keys=True)


def split_of(object_id: str, test_fraction: float = 0.1) -> str:
    """'test' for a stable pseudo-random ``test_fraction`` of ids (sha256 of the id), else 'train'."""
    h = int(hashlib.sha256(object_id.encode()).hexdigest()[:8], 16) / 0x100000000
    return "test" if h < test_fraction else "train"


@dataclass(frozen=True)
class Rejected:
    """An enumerated object the manifest cannot hold: its id, path, reason code and message."""

    id: str
    path: str
    reason: str
    message: str


def build_manifest(source: str, count: int | None, scales: Iterable[float] = DEFAULT_SCALES,
                   test_fraction: float = 0.1, progress: bool = False,
                   rejected: list | None = None, max_mesh_bytes: int = MAX_MESH_BYTES) -> list[ManifestEntry]:
    """Enumerate a source and hash each raw mesh. Every entry is validated exactly as
    `load_manifest` validates a line, so a built manifest always loads. Objects that cannot be
    entries (a missing or unreadable file, a directory or device, a file over ``max_mesh_bytes``,
    a path or symlink leaving the source root) are appended to ``rejected`` as `Rejected`, or, when it is None, logged as
    warnings (logger ``datagen.objects.manifest``; the command line prints them on stderr). ``count`` counts accepted objects (a rejected file does not take an object's place).
    Objects of the ``tasks`` source get their own scale instead of ``scales``."""
    scales = tuple(scales)
    if not scales or not all(_scale_ok(s) for s in scales):
        raise ValueError(f"manifest scales must be positive metres or 'native', got {scales}")
    scales = tuple(_scale_value(s) for s in scales)
    if len(set(scales)) != len(scales):
        raise ValueError(f"manifest scales must be distinct, got {scales}")
    if not 0 <= test_fraction <= 1:
        raise ValueError(f"test_fraction must be in [0, 1], got {test_fraction}")
    # file sources are enumerated lazily until `count` objects are accepted: a rejected entry does
    # not take an object's place
    lazy = canonical_source(source).partition(":")[0] in ("dir", "dexgraspnet")
    refs = iter_source(source, None if lazy else count)
    if progress:
        from tqdm import tqdm
        refs = tqdm(refs, desc="hashing", unit="obj", total=count)
    out = []

    def reject(ref, exc: ObjectError):
        r = Rejected(ref.object_id, ref.path, exc.reason.value, str(exc))
        if rejected is None:
            log.warning("skipped %s", r.message)
        else:
            rejected.append(r)

    for ref in refs:
        if count is not None and len(out) >= count:
            break
        try:
            resolve(ref.source, ref.path, ref.object_id, ref.family)  # inside the root, before reading
            # a task object has one scale, its own: its virtual joint's anchor is in metres at it
            sc = (task_objects.build(ref.path).scale_m,) if ref.source == "tasks" else scales
            e = ManifestEntry.of_ref(ref, sc, split_of(ref.object_id, test_fraction), max_mesh_bytes)
            out.append(_entry(json.loads(e.to_json()), ref.object_id))  # the loader's own checks
        except ObjectError as exc:
            reject(ref, exc)
    return out


def manifest_text(entries: Iterable[ManifestEntry]) -> str:
    """The JSON Lines text `write_manifest` writes (one entry per line)."""
    return "".join(e.to_json() + "\n" for e in entries)


def write_manifest(entries: Iterable[ManifestEntry], path: str | Path) -> Path:
    """Write atomically (`datagen._atomic`: a temp file renamed into place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, manifest_text(entries))
    return path


def _entry(obj, where: str, check_paths: bool = True) -> ManifestEntry:
    if not isinstance(obj, dict):
        raise ManifestError(Reason.MALFORMED_LINE, where, "a line must be a JSON object")
    missing, extra = set(_FIELDS) - set(obj), set(obj) - set(_FIELDS)
    if missing or extra:
        raise ManifestError(Reason.SCHEMA, where,
                            f"missing fields {sorted(missing)}, unknown fields {sorted(extra)}")
    for k, typ in _FIELDS.items():
        if not isinstance(obj[k], typ):
            raise ManifestError(Reason.SCHEMA, where, f"field {k!r} must be {typ.__name__}")
    if not _ID.match(obj["id"]):
        raise ManifestError(Reason.SCHEMA, where, f"id {obj['id']!r} is not [A-Za-z0-9._-]{{1,200}}")
    if not _SHA.match(obj["sha256"]):
        raise ManifestError(Reason.SCHEMA, where, "sha256 must be 64 lowercase hex digits")
    sc = obj["scales"]
    if not sc or not all(_scale_ok(s) for s in sc):
        raise ManifestError(Reason.SCHEMA, where, f"scales must be numbers in (0, 10) metres or 'native', got {sc}")
    if len(set(sc)) != len(sc):
        raise ManifestError(Reason.SCHEMA, where, f"scales must be distinct, got {sc}")
    if obj["split"] not in ("train", "test"):
        raise ManifestError(Reason.SCHEMA, where, f"split must be 'train' or 'test', got {obj['split']!r}")
    e = ManifestEntry(obj["id"], obj["source"], obj["path"], obj["family"], obj["sha256"],
                      tuple(_scale_value(s) for s in sc), obj["split"])
    try:
        canonical_source(e.source)  # source known
        if check_paths:
            e.ref()  # path inside its root (follows symlinks, so it depends on the files now)
    except SourceError as exc:
        raise ManifestError(Reason.UNKNOWN_SOURCE, where, exc.detail) from exc
    except ManifestError as exc:
        raise ManifestError(exc.reason, where, exc.detail) from exc
    return e


def load_manifest(path: str | Path, check_paths: bool = True) -> list[ManifestEntry]:
    """Read and validate a manifest; the first bad line raises ManifestError naming it.
    ``check_paths=False`` skips the file-system checks of each path (a job reading back its own
    manifest: its files are checked when each object is processed, and a file changed since must
    cost that object, not the job)."""
    path = Path(path)
    entries, seen = [], {}
    try:
        for n, line in _bounded.iter_lines(path, _bounded.MANIFEST_BYTES, _bounded.MANIFEST_LINE_BYTES, "manifest"):
            if not line.strip():
                continue
            where = f"{path}:{n}"
            try:
                obj = json.loads(line)
            except json.JSONDecodeError as exc:
                raise ManifestError(Reason.MALFORMED_LINE, where, f"not JSON ({exc.msg})") from exc
            except RecursionError:
                raise ManifestError(Reason.MALFORMED_LINE, where, "JSON nested too deeply") from None
            e = _entry(obj, where, check_paths)
            if e.id in seen:
                raise ManifestError(Reason.DUPLICATE_ID, where, f"id {e.id!r} already on line {seen[e.id]}")
            seen[e.id] = n
            entries.append(e)
    except _bounded.InputError as exc:
        raise ManifestError.of_input(exc) from None
    return entries
