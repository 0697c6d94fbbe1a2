"""Objects at scale: sources -> manifests -> processed objects (cached) -> distance queries.

Units and frames: a processed object lives in *normalized units* (centred at its bounding-box
centre, bounding-box half-diagonal 1); a manifest scale s in metres multiplies it, so the same
processed object serves every scale (0.06-0.12 m by default). Distance queries take points in
metres in the object frame plus the scale.

Public API::

    iter_source(uri, count) -> ObjectRef...          sources.py (procedural.py for the generator)
    build_manifest / write_manifest / load_manifest   manifest.py
    ProcessConfig                                     config.py (YAML via ProcessConfig.from_yaml)
    process_object(ref, cfg, root) -> ProcessedObject process.py (cache: cache.py, files: layout.py)
    prepare(manifest, cfg, root, workers)             prepare.py (the `datagen prepare` command)
    process_isolated(entry, cfg, root, timeout_s)     isolate.py (a child process with a time limit)
    MeshSDF(vertices, faces).query(points, scale)     sdf.py
    object_mjcf(...)                                  mjcf.py
    Reason, ObjectError, MeshProcessingError, ManifestError, SourceError   errors.py
"""

from .config import ProcessConfig
from .errors import ManifestError, MeshProcessingError, ObjectError, Reason, SourceError
from .manifest import DEFAULT_SCALES, ManifestEntry, build_manifest, load_manifest, write_manifest
from .mjcf import object_mjcf
from .prepare import prepare
from .process import ProcessedObject, load_processed, process_object
from .sdf import MeshSDF, SDFResult
from .sources import ObjectRef, iter_source

__all__ = [
    "ProcessConfig", "Reason", "ObjectError", "MeshProcessingError", "ManifestError", "SourceError",
    "DEFAULT_SCALES", "ManifestEntry", "build_manifest", "load_manifest", "write_manifest",
    "object_mjcf", "prepare", "ProcessedObject", "load_processed", "process_object",
    "MeshSDF", "SDFResult", "ObjectRef", "iter_source",
]
