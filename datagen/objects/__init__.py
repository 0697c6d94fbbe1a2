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

import importlib

# name -> its module; imported on first use, so a command that only checks its arguments (or a
# worker that needs one module) does not pay for trimesh, CoACD and torch (~3 s of imports)
_API = {
    "ProcessConfig": "config", "Reason": "errors", "ObjectError": "errors", "MeshProcessingError": "errors",
    "ManifestError": "errors", "SourceError": "errors", "DEFAULT_SCALES": "manifest", "ManifestEntry": "manifest",
    "build_manifest": "manifest", "load_manifest": "manifest", "write_manifest": "manifest", "object_mjcf": "mjcf",
    "prepare": "prepare", "ProcessedObject": "process", "load_processed": "process", "process_object": "process",
    "MeshSDF": "sdf", "SDFResult": "sdf", "ObjectRef": "sources", "iter_source": "sources",
}

__all__ = list(_API)


def __getattr__(name: str):
    if name in _API:
        value = getattr(importlib.import_module(f".{_API[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'datagen.objects' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
