"""The files a hand's MJCF/URDF is made of, and one content hash over their bytes.

A job (or a table written by ``datagen synth``) pins the hand it was made with: a copy of the spec
whose ``mjcf.sha256`` is `asset_sha256` of the asset then. Loading a pinned spec recomputes the hash
and refuses a hand whose files changed (`datagen.hands.load.load_hand`), so rows are never
evaluated on another hand than the one they were synthesized for.

The hash covers the main file, the MJCF files it includes, and every mesh, texture, height field
and skin file the model reads, each named by its path relative to the main file's folder (so the
same package installed elsewhere hashes the same), not MuJoCo's compiled model (which changes
with MuJoCo's version while the files do not).
"""

from __future__ import annotations

import hashlib
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from .spec import HandSpecError

__all__ = ["MAX_ASSET_FILE_BYTES", "asset_files", "asset_sha256", "file_sha256"]

MAX_ASSET_FILE_BYTES = 512 * 2**20  # one mesh or XML file of a hand; larger is refused, not read
_CHUNK = 2**20


def file_sha256(path: Path) -> str:
    """sha256 of a regular file's bytes, read in 1 MiB chunks (devices, FIFOs and files over
    `MAX_ASSET_FILE_BYTES` refused, naming the file)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise HandSpecError(path, f"hand asset file cannot be read: {exc.strerror}") from None
    import stat

    if not stat.S_ISREG(st.st_mode):
        raise HandSpecError(path, "hand asset file is not a regular file", "point the MJCF/URDF at real files")
    if st.st_size > MAX_ASSET_FILE_BYTES:
        raise HandSpecError(path, f"hand asset file is {st.st_size / 2**20:.0f} MiB, over the "
                            f"{MAX_ASSET_FILE_BYTES // 2**20} MiB limit", "simplify the mesh")
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_CHUNK), b""):
            h.update(block)
    return h.hexdigest()


def _mjcf_includes(path: Path, main_dir: Path, seen: set[Path]) -> None:
    """Add ``path`` and the files it ``<include>``s (recursively) to ``seen``."""
    if path in seen:
        return
    seen.add(path)
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return  # MuJoCo's own reader names the problem when the hand is loaded
    for inc in root.iter("include"):
        name = inc.get("file")
        if not name:
            continue
        for folder in (path.parent, main_dir):
            cand = (folder / name).resolve()
            if cand.is_file():
                _mjcf_includes(cand, main_dir, seen)
                break


def _mjcf_files(source: Path) -> set[Path]:
    import mujoco

    files: set[Path] = set()
    _mjcf_includes(source, source.parent, files)
    try:
        spec = mujoco.MjSpec.from_file(str(source))
    except Exception:  # noqa: BLE001 - unreadable: flatten_hand reports it with MuJoCo's message
        return files

    def under(folder: str) -> Path:
        return (source.parent / folder) if folder and not os.path.isabs(folder) else Path(folder or source.parent)

    meshdir, texdir = under(spec.meshdir), under(spec.texturedir)
    for mesh in spec.meshes:
        if mesh.file:
            files.add((meshdir / mesh.file).resolve())
    for tex in spec.textures:
        for name in [tex.file, *getattr(tex, "cubefiles", [])]:
            if name:
                files.add((texdir / name).resolve())
    for kind in ("hfields", "skins"):
        for item in getattr(spec, kind, []):
            if getattr(item, "file", ""):
                files.add((source.parent / item.file).resolve())
    return files


def asset_files(source: str | Path) -> list[Path]:
    """Every file the hand ``source`` (MJCF or URDF) is read from, sorted, the main file first."""
    source = Path(source).resolve()
    if source.suffix.lower() == ".urdf":
        from .mjcf import urdf_mesh_files

        files = {source, *urdf_mesh_files(source)}
    else:
        files = _mjcf_files(source)
    return [source] + sorted(f for f in files if f != source)


def asset_sha256(source: str | Path) -> str:
    """sha256 over (path relative to the main file's folder, sha256 of the bytes) of every file in
    `asset_files`: one hash that changes when any byte of the hand's files does."""
    source = Path(source).resolve()
    lines = []
    for f in asset_files(source):
        rel = Path(os.path.relpath(f, source.parent)).as_posix()
        lines.append(f"{rel}\t{file_sha256(f)}\n")
    return hashlib.sha256("".join(sorted(lines)).encode()).hexdigest()
