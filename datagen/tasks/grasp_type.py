"""Grasp types as data: the contact set a force-closure grasp is synthesized with.

A grasp type YAML (``datagen/tasks/grasp_types/<name>.yaml`` for the built-in ones) names the
links beyond the fingertips that take part in the grasp, by role, so one file serves every hand
(the roles are derived from the hand's kinematic tree: `datagen.synth.links`):

* ``palm`` and ``phalanges`` (every other link on a finger's chain), each ``pull`` (pulled onto
  the surface by the distance term, like a fingertip, and counted in the grasp wrench space while
  touching) or ``candidate`` (counted in the GWS while touching, not pulled);

plus ``init`` (`datagen.tasks.InitConfig` fields over the task's: a palm distance, closing the
fingers onto the object) and ``synth`` (`datagen.synth.SynthConfig` fields for this type's grasps,
a mapping such as ``weights`` merged key by key: an energy term, more starts; a layer of the recipe
between the task and the user's config, `datagen.pipeline.recipe`). A ``hands`` block adapts the
type to one hand, as a task's does: per hand name, ``init`` and ``synth`` fields over the type's
own (`GraspType.for_hand`; the recipe of that hand records the synth layer it gives)::

    hands:
      leap: {init: {distance_m: [0.015, 0.04]}}

``precision`` is the fingertip grasp of the paper (no extra contacts);
``power`` adds the palm and the phalanges.

Which type a grasp gets is the recipe's ``grasp_types`` (a `GraspMix`: per object size, a share
of each type; `datagen.pipeline.resolve`), for force-closure tasks on every fingertip; every row
records its ``grasp_type``. A task that names its own fingertips (the paper's Table II tasks) is
its own contact set: its rows record ``task``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

from datagen.config import Config, merge_layers
from datagen.errors import ConfigError
from datagen.tasks.spec import builtin_names, builtin_or_file

__all__ = ["CONTACT_MODES", "CONTACT_ROLES", "GRASP_TYPE_DIR", "TASK_GRASP_TYPE", "FlatBand", "GraspBand", "GraspMix",
           "GraspType", "GraspTypeHand", "builtin_grasp_types", "load_grasp_type"]

GRASP_TYPE_DIR = Path(__file__).parent / "grasp_types"
CONTACT_ROLES = ("palm", "phalanges")
CONTACT_MODES = ("pull", "candidate")
TASK_GRASP_TYPE = "task"  #: the grasp_type of rows of a task that names its own fingertips
FIXED_SYNTH = ("grasp_type", "task", "seed", "squeeze_kp")  #: synth fields the job sets, never a grasp type


def _check_fields(where: str, init: Mapping[str, Any], synth: Mapping[str, Any]) -> None:
    """Refuse ``init`` fields that are not `InitConfig`'s and ``synth`` fields the job sets."""
    from datagen.tasks.spec import InitConfig

    unknown = sorted(set(init) - set(InitConfig.__dataclass_fields__))
    if unknown:
        raise ConfigError(f"{where}: unknown init field(s) {unknown}", f"known: {sorted(InitConfig.__dataclass_fields__)}")
    fixed = sorted(set(synth) & set(FIXED_SYNTH))
    if fixed:  # (unknown fields and bad values: refused by the recipe's resolution, naming the type)
        raise ConfigError(f"{where}: synth.{fixed[0]} is set by the job, not by a grasp type")


@dataclass(frozen=True)
class GraspTypeHand(Config):
    """A grasp type's adaptation to one hand: ``init`` and ``synth`` fields over the type's own."""

    init: Mapping[str, Any] = field(default_factory=dict)  #: `InitConfig` fields
    synth: Mapping[str, Any] = field(default_factory=dict)  #: `SynthConfig` fields (mappings merged key by key)


@dataclass(frozen=True)
class GraspType(Config):
    """One grasp type: its extra contact links by role and its initial-pose fields."""

    name: str
    #: role ("palm", "phalanges") -> "pull" or "candidate"; the fingertips are always contacts
    contacts: Mapping[str, str] = field(default_factory=dict)
    #: `InitConfig` fields replacing the task's (e.g. ``distance_m``, ``close``)
    init: Mapping[str, Any] = field(default_factory=dict)
    #: `SynthConfig` fields of this type's grasps (mappings merged key by key), e.g. ``weights``:
    #: over the task's, under the user's config and flags (`datagen.pipeline.Recipe.synth_for`)
    synth: Mapping[str, Any] = field(default_factory=dict)
    #: hand name -> `GraspTypeHand` (its ``init`` / ``synth`` fields over the type's, for that hand only)
    hands: Mapping[str, GraspTypeHand] = field(default_factory=dict)

    def __post_init__(self):
        from datagen.tasks.spec import InitConfig

        if not self.name or not self.name.replace("_", "").isalnum():
            raise ConfigError(f"grasp type name must be a simple identifier, got {self.name!r}")
        if self.name == TASK_GRASP_TYPE:
            raise ConfigError(f"grasp type name {TASK_GRASP_TYPE!r} is reserved (rows of tasks with their own fingertips)")
        for role, mode in dict(self.contacts).items():
            if role not in CONTACT_ROLES:
                raise ConfigError(f"grasp type {self.name!r}: unknown contact role {role!r}", f"roles: {list(CONTACT_ROLES)}")
            if mode not in CONTACT_MODES:
                raise ConfigError(f"grasp type {self.name!r}: contacts.{role} must be one of {list(CONTACT_MODES)}, "
                                  f"got {mode!r}")
        _check_fields(f"grasp type {self.name!r}", self.init, self.synth)
        if not isinstance(self.hands, Mapping):
            raise ConfigError(f"grasp type {self.name!r}: hands must map hand names to {{init, synth}}, "
                              f"got {type(self.hands).__name__}")
        hands = {}
        for k, v in dict(self.hands).items():
            where = f"grasp type {self.name!r}: hands.{k}"
            if not isinstance(k, str) or not k:
                raise ConfigError(f"grasp type {self.name!r}: hands: a hand name must be a non-empty string, got {k!r}")
            hands[k] = v if isinstance(v, GraspTypeHand) else GraspTypeHand.from_dict(v, where)
            _check_fields(where, hands[k].init, hands[k].synth)
        object.__setattr__(self, "hands", hands)
        for k in hands:  # every hand's init must be a valid InitConfig (over the defaults)
            try:
                InitConfig.from_dict({**InitConfig().to_dict(), **dict(self.for_hand(k).init)})
            except ConfigError as e:
                raise ConfigError(f"grasp type {self.name!r}: hands.{k}.init: {e}") from None

    def for_hand(self, hand_name: str) -> "GraspType":
        """This type as hand ``hand_name`` gets it: its ``hands`` entry's ``init`` and ``synth``
        fields over the type's (nested mappings merged key by key); the result has no ``hands``."""
        o = self.hands.get(hand_name)
        if o is None:
            return self if not self.hands else replace(self, hands={})
        return replace(self, init={**dict(self.init), **dict(o.init)}, synth=merge_layers(self.synth, o.synth), hands={})

    def role(self, name: str) -> str | None:
        """``"pull"``, ``"candidate"`` or None (the role takes no part)."""
        return dict(self.contacts).get(name)

    @property
    def extra_contacts(self) -> bool:
        return bool(self.contacts)

    def apply_init(self, init):
        """The task's `InitConfig` with this type's fields over it."""
        if not self.init:
            return init
        return type(init).from_dict({**init.to_dict(), **dict(self.init)}, f"grasp type {self.name!r}: init")


@dataclass(frozen=True)
class GraspBand(Config):
    """The grasp types of objects up to one size: ``mix`` maps type names (or YAML paths) to
    shares (summing to 1)."""

    max_scale_m: float | None = None  #: objects of at most this scale (m); None: every larger one
    mix: Mapping[str, float] = field(default_factory=lambda: {"precision": 1.0})  #: type name -> share of the grasps
    #: the mix of these objects resting on a table (null: mix); one lying flat takes grasp_types.flat's
    tabletop: Mapping[str, float] | None = None

    def __post_init__(self):
        if self.max_scale_m is not None and not (math.isfinite(self.max_scale_m) and self.max_scale_m > 0):
            raise ConfigError(f"grasp_types: max_scale_m must be a positive number of metres or null, got {self.max_scale_m}")
        for name, mix in (("mix", self.mix), ("tabletop", self.tabletop)):
            if mix is None:
                continue
            shares = dict(mix)
            if not shares or any(not (math.isfinite(v) and v >= 0) for v in shares.values()) \
                    or abs(sum(shares.values()) - 1.0) > 1e-6:
                raise ConfigError(f"grasp_types: {name} must map grasp types to shares >= 0 summing to 1, got {shares}")

    def mix_for(self, tabletop: bool) -> Mapping[str, float]:
        """The shares of this band's objects, floating or resting on a table."""
        return self.tabletop if tabletop and self.tabletop is not None else self.mix


@dataclass(frozen=True)
class FlatBand(Config):
    """The grasp types of an object lying flat on a table: its top at most ``max_height_m`` above
    the table in its stable pose (`datagen.objects.tabletop.Footprint`), whatever its scale."""

    max_height_m: float = 0.04  #: m, the highest top above the table that counts as flat
    mix: Mapping[str, float] = field(default_factory=lambda: {"precision": 1.0})  #: type name -> share of the grasps

    def __post_init__(self):
        if not (math.isfinite(self.max_height_m) and self.max_height_m > 0):
            raise ConfigError(f"grasp_types.flat: max_height_m must be a positive number of metres, got {self.max_height_m}")
        GraspBand(mix=self.mix)  # the same check of the shares


@dataclass(frozen=True)
class GraspMix(Config):
    """Which grasp types a force-closure task's grasps get, by object size (the recipe's
    ``grasp_types``): the first band whose ``max_scale_m`` holds the object's scale applies, and
    its ``mix`` splits each object's grasps between types (largest remainder, in the mix's order),
    its ``tabletop`` mix where the object rests on a table; with ``flat``, an object resting on a
    table no higher than its ``max_height_m`` gets its mix instead, at any scale."""

    bands: tuple[GraspBand, ...] = (GraspBand(),)  #: by increasing max_scale_m, the last one open (null)
    #: tabletop objects lying flat (their top at most max_height_m above the table) get this mix instead of the bands' (null: the bands for every object)
    flat: FlatBand | None = None

    def __post_init__(self):
        if not self.bands or self.bands[-1].max_scale_m is not None:
            raise ConfigError("grasp_types.bands must end with a band without max_scale_m (every larger object)")
        sizes = [b.max_scale_m for b in self.bands[:-1]]
        if any(s is None for s in sizes) or sizes != sorted(sizes) or len(set(sizes)) != len(sizes):
            raise ConfigError(f"grasp_types.bands: max_scale_m must increase, got {sizes}")
        for mix in self._mixes():
            for name in mix:
                load_grasp_type(name)  # an unknown type is refused here, naming it

    @classmethod
    def single(cls, name: str) -> "GraspMix":
        """Every grasp of one type."""
        return cls(bands=(GraspBand(mix={name: 1.0}),))

    def _mixes(self) -> list[Mapping[str, float]]:
        """Every mix of the bands (floating, tabletop, flat), in that order."""
        out = [b.mix for b in self.bands] + [b.tabletop for b in self.bands if b.tabletop is not None]
        return out + ([self.flat.mix] if self.flat is not None else [])

    def types(self) -> list[str]:
        """Every grasp type the bands use (share > 0), in order of first use."""
        out: list[str] = []
        for mix in self._mixes():
            out += [k for k, v in mix.items() if v > 0 and k not in out]
        return out

    def counts(self, scale: float, n: int, height_m: float | None = None) -> dict[str, int]:
        """Grasps of each type (share > 0) for ``n`` grasps on an object of ``scale`` m, resting
        on a table with its top ``height_m`` above it (None: floating)."""
        if self.flat is not None and height_m is not None and height_m <= self.flat.max_height_m + 1e-9:
            shares = self.flat.mix
        else:
            band = next(b for b in self.bands if b.max_scale_m is None or scale <= b.max_scale_m + 1e-9)
            shares = band.mix_for(height_m is not None)
        mix = [(k, v) for k, v in shares.items() if v > 0]
        raw = [v * n for _, v in mix]
        out = [int(math.floor(x)) for x in raw]
        order = sorted(range(len(mix)), key=lambda i: (-(raw[i] - out[i]), i))
        for i in order[:n - sum(out)]:
            out[i] += 1
        return {k: c for (k, _), c in zip(mix, out) if c > 0}


def builtin_grasp_types() -> list[str]:
    """Names of the built-in grasp types (``datagen/tasks/grasp_types/*.yaml``)."""
    return builtin_names(GRASP_TYPE_DIR)


def load_grasp_type(name_or_path: str | Path) -> GraspType:
    """A built-in grasp type by name (``precision``, ``power``) or a YAML file."""
    return GraspType.from_yaml(builtin_or_file(name_or_path, GRASP_TYPE_DIR, "grasp type"))
