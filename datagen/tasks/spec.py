"""A task as data: its task wrench space, its fingertips, its initial hand pose, its test.

A task YAML (``datagen/tasks/specs/<name>.yaml`` for the built-in ones) is one mapping of
`TaskSpec` fields; ``init`` is an `InitConfig` mapping (read by `datagen.synth.init`) and
``eval`` the task's physical test (parsed by `datagen.tasks.evaluation`, read by
`datagen.eval`). Synthesis and evaluation both read tasks from here, so neither reaches into the
other.

A ``hands`` block adapts a task to hands other than the one its pose was written for: per hand
name, ``init`` (InitConfig fields replacing the task's: a hand's own aim point, curl, thumb
hint) and ``fingers`` (e.g. without the little finger). `TaskSpec.for_hand` applies it::

    hands:
      allegro: {init: {target_m: [0.0, 0.06, 0.02], curl: 0.4}}

A ``synth`` block holds the `SynthConfig` settings the task's synthesis starts from, e.g. exact
contacts and multi-start: one layer of the recipe (`datagen.pipeline.resolve` puts it over the
preset and puts the user's settings on top).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

from datagen.config import Config
from datagen.errors import ConfigError

__all__ = ["SPEC_DIR", "HandOverride", "InitConfig", "TaskSpec", "builtin_tasks", "load_task"]

SPEC_DIR = Path(__file__).parent / "specs"


@dataclass(frozen=True)
class InitConfig(Config):
    """Initial hand poses (see :mod:`datagen.synth.init`). Vectors are in the object frame."""

    kind: str = "surround"  #: "surround" (palm faces the object from its hull), "above", "approach", "rim" (a pinch across the object's footprint from above) or "wrap" (palm across the object's longest axis, the pinch axis round its thin side)
    distance_m: tuple[float, float] = (0.03, 0.06)  #: palm distance from the convex hull, uniform range
    roll_deg: float = 180.0  #: jitter about the approach axis, +-
    tilt_deg: float = 15.0  #: jitter of the approach axis, +-
    offset_m: float = 0.01  #: lateral jitter of the palm origin, +-
    approach: tuple[float, float, float] = (0.0, 0.0, -1.0)  #: "approach": palm approach direction ("above": -z)
    thumb: tuple[float, float, float] | None = None  #: "approach": preferred thumb direction (None: random roll)
    target_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: "approach": the point the palm (or the fingertips, see aim) aims at, m
    curl: float = 0.0  #: fingers start this fraction (0..1) of the way from open to flexed (a hook)
    aim: str = "palm"  #: "approach": what lands on target_m, "palm" (palm origin) or "fingertips" (task tips' centre)

    def __post_init__(self):
        if self.kind not in ("surround", "above", "approach", "rim", "wrap"):
            raise ConfigError(f"init.kind must be 'surround', 'above', 'approach', 'rim' or 'wrap', got {self.kind!r}")
        if self.aim not in ("palm", "fingertips"):
            raise ConfigError(f"init.aim must be 'palm' or 'fingertips', got {self.aim!r}")
        if not (isinstance(self.curl, (int, float)) and 0.0 <= self.curl <= 1.0):
            raise ConfigError(f"init.curl must be a number in [0, 1], got {self.curl!r}")
        lo, hi = self.distance_m
        if not 0 <= lo <= hi:
            raise ConfigError(f"init.distance_m must be an increasing pair >= 0, got {self.distance_m}")
        for name in ("approach", "thumb", "target_m"):
            v = getattr(self, name)
            if v is None:
                continue
            if len(v) != 3 or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in v):
                raise ConfigError(f"init.{name} must be 3 finite numbers, got {v!r}")
            if name != "target_m" and math.hypot(*v) < 1e-9:
                raise ConfigError(f"init.{name} must be a non-zero direction, got {v!r}")
        if self.thumb is not None:
            a, t = self.approach, self.thumb
            cos = abs(sum(x * y for x, y in zip(a, t))) / (math.hypot(*a) * math.hypot(*t))
            if cos > 0.99:
                raise ConfigError(f"init.thumb {t} is (nearly) parallel to init.approach {a}")


@dataclass(frozen=True)
class HandOverride(Config):
    """A task's adaptation to one hand: ``init`` fields replacing the task's (checked as an
    `InitConfig` when applied) and the contact ``fingers`` (None: the task's)."""

    init: Mapping[str, Any] = field(default_factory=dict)
    fingers: tuple[str, ...] | None = None

    def __post_init__(self):
        unknown = sorted(set(self.init) - {f for f in InitConfig.__dataclass_fields__})
        if unknown:
            raise ConfigError(f"hands.init: unknown InitConfig field(s) {unknown}",
                              f"known: {sorted(InitConfig.__dataclass_fields__)}")


@dataclass(frozen=True)
class TaskSpec(Config):
    """A task as data: the TWS (w_t, gamma), which fingertips make contact, the initial pose, the test."""

    name: str
    w_t: tuple[float, ...] = (0, 0, 0, 0, 0, 1)  #: task wrench direction [force, torque] (object frame)
    gamma_deg: float = 180.0  #: TWS half-angle, degrees (180: force closure)
    fingers: tuple[str, ...] | str = "all"  #: the contact fingertips (hand finger names) or "all"
    init: InitConfig = field(default_factory=InitConfig)
    eval: str | dict = "six_direction"  #: "six_direction" or the task test mapping (see datagen.tasks.evaluation)
    hands: Mapping[str, HandOverride] = field(default_factory=dict)  #: per-hand init / fingers (see for_hand)
    #: SynthConfig fields this task's synthesis starts from (e.g. ``exact_contacts``,
    #: ``seeds_per_grasp``, ``weights: {task: ...}``): a layer of the recipe, over the preset and
    #: under the user's settings (`datagen.pipeline.resolve`)
    synth: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "w_t", tuple(float(x) for x in self.w_t))  # equal specs, equal hashes
        if isinstance(self.fingers, list):
            object.__setattr__(self, "fingers", tuple(self.fingers))
        if len(self.w_t) != 6 or not any(abs(float(x)) > 0 for x in self.w_t):
            raise ConfigError(f"task {self.name!r}: w_t must be 6 numbers, not all zero, got {self.w_t}")
        if not 0 < self.gamma_deg <= 180:
            raise ConfigError(f"task {self.name!r}: gamma_deg must lie in (0, 180], got {self.gamma_deg}")
        hands = {str(k): v if isinstance(v, HandOverride) else HandOverride.from_dict(v, f"task {self.name!r}: hands.{k}")
                 for k, v in dict(self.hands).items()}
        object.__setattr__(self, "hands", hands)
        for k in hands:
            self.for_hand(k)  # every hand's init must be a valid InitConfig

    def for_hand(self, hand_name: str) -> "TaskSpec":
        """This task as hand ``hand_name`` runs it: its ``hands`` entry's init fields and fingers
        applied (the task itself when it has none); the result has no ``hands`` block."""
        o = self.hands.get(hand_name)
        if o is None:
            return self if not self.hands else replace(self, hands={})
        init = InitConfig.from_dict({**self.init.to_dict(), **dict(o.init)}, f"task {self.name!r}: hands.{hand_name}.init")
        return replace(self, init=init, fingers=o.fingers if o.fingers is not None else self.fingers, hands={})


def builtin_names(directory: Path) -> list[str]:
    """Names of the built-in YAML files in ``directory`` (tasks, grasp types)."""
    return sorted(p.stem for p in directory.glob("*.yaml"))


def builtin_or_file(name_or_path: str | Path, directory: Path, kind: str) -> Path:
    """The YAML file of a built-in ``kind`` ("task", "grasp type") by name, or a user's file by
    path; `ConfigError` naming it (with the built-in names) when there is none."""
    path = Path(name_or_path)
    if not path.suffix:
        path = directory / f"{name_or_path}.yaml"
        if not path.is_file():
            raise ConfigError(f"unknown {kind} {name_or_path!r}",
                              f"built-in {kind}s: {builtin_names(directory)}, or pass a YAML file")
    if not path.is_file():
        raise ConfigError(f"{kind} file {path} does not exist")
    return path


def builtin_tasks() -> list[str]:
    """Names of the built-in tasks (``datagen/tasks/specs/*.yaml``)."""
    return builtin_names(SPEC_DIR)


def load_task(name_or_path: str | Path) -> TaskSpec:
    """A built-in task by name (``force_closure``, ...) or a YAML task file."""
    return TaskSpec.from_yaml(builtin_or_file(name_or_path, SPEC_DIR, "task"))
