"""Typed configuration of grasp synthesis, loadable from YAML (one ``from_dict`` each)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

__all__ = ["ConfigError", "EnergyWeights", "InitConfig", "SynthConfig", "TaskSpec", "load_task", "builtin_tasks"]

TASK_DIR = Path(__file__).parent / "tasks"


class ConfigError(ValueError):
    """A malformed synthesis config or task spec; the message names the file/field and the fix."""


def _from_dict(cls, data: dict | None, where: str):
    data = dict(data or {})
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown field(s) {unknown}; known: {sorted(known)}")
    try:
        return cls(**data)
    except TypeError as exc:
        raise ConfigError(f"{where}: {exc}") from exc


@dataclass(frozen=True)
class EnergyWeights:
    """Weights of the energy terms; 0 disables a term. Units make each term ~1 at a typical error."""

    task: float = 1.0  #: mean over K of -cos(s_Wt, s_Wg) (dimensionless, in [-1, 1])
    distance: float = 1e4  #: per m^2 of summed squared fingertip-surface distance (1 cm -> 1)
    penetration: float = 1e5  #: per m^2 of summed squared sphere penetration (1 mm -> 0.1)
    self_penetration: float = 1e5  #: per m^2 of summed squared sphere-pair overlap
    joint_limits: float = 1e2  #: per rad of summed joint-limit violation

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and v >= 0 and math.isfinite(v)):
                raise ConfigError(f"EnergyWeights.{f.name} must be a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class InitConfig:
    """Initial hand poses (see :mod:`datagen.synth.init`). Vectors are in the object frame."""

    kind: str = "surround"  #: "surround" (palm faces the object from its hull), "above" or "approach"
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
        if self.kind not in ("surround", "above", "approach"):
            raise ConfigError(f"init.kind must be 'surround', 'above' or 'approach', got {self.kind!r}")
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
class TaskSpec:
    """A task as data: the TWS (w_t, gamma), which fingertips make contact, the initial pose."""

    name: str
    w_t: tuple[float, ...] = (0, 0, 0, 0, 0, 1)
    gamma_deg: float = 180.0
    fingers: tuple[str, ...] | str = "all"
    init: InitConfig = field(default_factory=InitConfig)
    eval: str | dict = "six_direction"  #: "six_direction" or the task test mapping (see datagen.eval.tasks)

    def __post_init__(self):
        if len(self.w_t) != 6 or not any(abs(float(x)) > 0 for x in self.w_t):
            raise ConfigError(f"task {self.name!r}: w_t must be 6 numbers, not all zero, got {self.w_t}")
        if not 0 < self.gamma_deg <= 180:
            raise ConfigError(f"task {self.name!r}: gamma_deg must lie in (0, 180], got {self.gamma_deg}")

    @classmethod
    def from_dict(cls, data: dict, where: str = "task") -> "TaskSpec":
        data = dict(data)
        data["init"] = _from_dict(InitConfig, _tuples(data.get("init")), f"{where}: init")
        if "w_t" in data:
            data["w_t"] = tuple(float(x) for x in data["w_t"])
        if isinstance(data.get("fingers"), list):
            data["fingers"] = tuple(data["fingers"])
        return _from_dict(cls, data, where)


def _tuples(d: dict | None) -> dict:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in (d or {}).items()}


def builtin_tasks() -> list[str]:
    return sorted(p.stem for p in TASK_DIR.glob("*.yaml"))


def load_task(name_or_path: str | Path) -> TaskSpec:
    """A built-in task by name (``force_closure``, ...) or a YAML task file."""
    path = Path(name_or_path)
    if not path.suffix:
        path = TASK_DIR / f"{name_or_path}.yaml"
        if not path.is_file():
            raise ConfigError(f"unknown task {name_or_path!r}; built-in tasks: {builtin_tasks()} (or pass a YAML file)")
    if not path.is_file():
        raise ConfigError(f"task file {path} does not exist")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"task file {path}: not valid YAML ({exc})") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"task file {path}: expected a mapping of task fields")
    return TaskSpec.from_dict(data, where=str(path))


@dataclass(frozen=True)
class SynthConfig:
    """Optimizer and energy settings (defaults follow the paper and NOTES §2)."""

    iters: int = 500
    num_directions: int = 100  #: K, wrench directions resampled every iteration
    delta_deg: float = 15.0
    mu: float = 0.5  #: friction coefficient of the GWS model
    normalize: bool = True  #: contact position normalization
    contact_model: str = "pcf"  #: "pcf" point contact with friction, "sfc" soft finger (torsional friction)
    torsional_mu: float = 0.0  #: SFC torsional friction coefficient, m (torque <= torsional_mu * normal force)
    task_energy_kind: str = "cos"  #: "cos" (paper) or "l2" (ablation)
    weights: EnergyWeights = field(default_factory=EnergyWeights)
    step_translation_m: float = 0.002
    step_rotation_rad: float = 0.02
    step_joint_rad: float = 0.03
    step_decay: float = 0.95  #: step multiplier every `decay_every` iterations
    decay_every: int = 50
    momentum: float = 0.9  #: m <- (momentum * m + g) / 2 on per-group normalized gradients
    squeeze_mode: str = "force"  #: pregrasp/squeeze: "force" (balanced grip forces), "normal" or "joint" (see squeeze.py)
    squeeze_force_n: float = 10.0  #: "force": largest fingertip grip force, N (10 N: best of 2/4/10/20 in MuJoCo holds)
    squeeze_kp: float = 5.0  #: "force": position-actuator stiffness the squeeze is computed for, N m/rad (eval protocol)
    squeeze_gap_m: float = 0.002  #: "force": extra fingertip travel along the normal (sphere overshoot), m
    squeeze_m: float = 0.01  #: "normal": fingertips move this far out (pregrasp) / in (squeeze) along the normals
    squeeze_rad: float = 0.1  #: "joint": pregrasp opens each joint by up to this towards the open pose
    contact_threshold_m: float = 0.005  #: fingertips closer than this count as in contact
    sphere_margin_m: float = 0.0015  #: spheres overshoot the hand's collision shapes (<= 2.8 mm): they may sink this far
    exact_contacts: bool = False  #: exact mesh SDF for contacts while optimizing (final contacts always exact)
    seeds_per_grasp: int = 1  #: multi-start: initial poses per output grasp; the best after seed_select_iter goes on
    seed_select_iter: int = 80  #: iterations every seed runs before the best seed of each grasp is kept
    seed: int = 0

    def __post_init__(self):
        if self.seeds_per_grasp < 1 or self.seed_select_iter < 1:
            raise ConfigError(f"SynthConfig: seeds_per_grasp and seed_select_iter must be >= 1, "
                              f"got {self.seeds_per_grasp}, {self.seed_select_iter}")
        if self.iters < 1 or self.num_directions < 1:
            raise ConfigError(f"SynthConfig: iters and num_directions must be >= 1, got {self.iters}, {self.num_directions}")
        if self.task_energy_kind not in ("cos", "l2"):
            raise ConfigError(f"SynthConfig.task_energy_kind must be 'cos' or 'l2', got {self.task_energy_kind!r}")
        if not 0 <= self.delta_deg <= 45:
            raise ConfigError(f"SynthConfig.delta_deg must lie in [0, 45], got {self.delta_deg}")
        if self.contact_model not in ("pcf", "sfc") or self.torsional_mu < 0:
            raise ConfigError(f"SynthConfig.contact_model must be 'pcf' or 'sfc' and torsional_mu >= 0, "
                              f"got {self.contact_model!r}, {self.torsional_mu}")
        if self.squeeze_mode not in ("force", "normal", "joint"):
            raise ConfigError(f"SynthConfig.squeeze_mode must be 'force', 'normal' or 'joint', got {self.squeeze_mode!r}")
        if not self.mu > 0:
            raise ConfigError(f"SynthConfig.mu must be > 0, got {self.mu}")

    @classmethod
    def from_dict(cls, data: dict | None, where: str = "synth config") -> "SynthConfig":
        data = dict(data or {})
        if "weights" in data:
            data["weights"] = _from_dict(EnergyWeights, data["weights"], f"{where}: weights")
        return _from_dict(cls, data, where)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
