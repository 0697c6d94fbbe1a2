"""Pinned hands: the copy of a hand's spec that a job directory (or a table's folder) keeps.

Rows name their hand (``hand``: the spec's ``name``). So that any command can load that hand again
from the rows' folder alone, wherever it has been moved, the folder keeps ``hands/<name>.yaml``:
the spec as it was used, with its asset referenced absolutely (or inside its package) and the
content hash of the asset's files (`asset.asset_sha256`), which loading checks::

    JOB/hands/myhand.yaml          # a job's hand (written by `datagen run` before any shard)
    TABLE_DIR/hands/myhand.yaml    # the hand of `datagen synth --out TABLE_DIR/t.parquet`

`datagen.hands.load.load_hand` (``base=``) looks there first, then at the built-in hands.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
from pathlib import Path

from .asset import asset_sha256
from .mjcf import resolve_asset
from .spec import AssetRef, HandSpec, HandSpecError, dump_spec, load_spec

__all__ = ["HANDS_DIR", "pin_hand", "pinned_path", "pinned_spec"]

HANDS_DIR = "hands"


def pinned_path(base: str | Path, name: str) -> Path | None:
    """``base/hands/<name>.yaml``, or None when ``name`` is no hand name (rows are user data: a
    name with a path separator never reaches the file system)."""
    if not name or not name.replace("_", "").replace("-", "").isalnum():
        return None
    return Path(base) / HANDS_DIR / f"{name}.yaml"


def pinned_spec(spec: HandSpec) -> HandSpec:
    """``spec`` with its asset located independently of the spec file (a package path stays one; a
    user's file becomes absolute) and ``mjcf.sha256`` set to the asset's current hash. A spec that
    is already pinned keeps its hash (`load_hand` has checked it)."""
    source = resolve_asset(spec.mjcf, spec.source_file)
    path = spec.mjcf.path if spec.mjcf.package else str(source)
    digest = spec.mjcf.sha256 or asset_sha256(source)
    return dataclasses.replace(spec, mjcf=AssetRef(path=path, package=spec.mjcf.package, sha256=digest))


def _header(spec: HandSpec, origin: str | None) -> str:
    pkg = spec.mjcf.package
    try:
        version = f" {importlib.metadata.version(pkg)}" if pkg else ""
    except importlib.metadata.PackageNotFoundError:
        version = ""
    where = f"package {pkg}{version}, {spec.mjcf.path}" if pkg else spec.mjcf.path
    return (f"Pinned copy of hand spec {spec.name!r}" + (f" (from {origin})" if origin else "") + ".\n"
            f"Asset: {where}; mjcf.sha256 is the hash of its files, checked whenever this hand is loaded.\n"
            "Rows whose `hand` is this name are loaded with this file; do not edit it.")


def pin_hand(spec: HandSpec, base: str | Path, *, write: bool = True) -> Path:
    """Write the pinned copy of ``spec`` to ``base/hands/<name>.yaml`` (atomically) and return its
    path. An existing copy with the same content is kept; one with other content (another spec
    under the same name, or the asset's files changed since) raises `HandSpecError` naming both.
    ``write=False`` only checks (a command that writes its output last refuses early)."""
    pinned = pinned_spec(spec)
    path = pinned_path(base, spec.name)
    assert path is not None  # HandSpec validates its name
    if path.is_file():
        old = load_spec(path)
        if old.to_dict() == pinned.to_dict():
            return path
        what = ("its asset's files changed" if old.mjcf.sha256 != pinned.mjcf.sha256
                and dataclasses.replace(old, mjcf=pinned.mjcf, source_file=None).to_dict()
                == dataclasses.replace(pinned, source_file=None).to_dict() else "its content differs")
        raise HandSpecError(path, f"holds another hand named {spec.name!r} than {spec.source_file or spec.name} "
                            f"({what})", "use the hand it was made with, another output folder, or give the "
                            "new hand another name")
    if write:
        path.parent.mkdir(parents=True, exist_ok=True)
        dump_spec(pinned, path, _header(pinned, spec.source_file))
    return path
