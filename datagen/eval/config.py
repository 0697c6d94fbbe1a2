"""Every constant of the MuJoCo evaluation in one validated config, loadable from YAML.

Defaults reproduce the public six-direction hold test (NOTES §3). Units: metres, seconds,
newtons, kilograms; angles in degrees where the field name says ``_deg``. The simulated world
is the object frame: the object starts at the origin with the identity pose, at scale
``object_scale_m`` metres per normalized unit (the row column of that name).

A task named in ``hold_tasks`` (default ``force_closure``) gets the six-direction test; any
other task is looked up in ``tasks`` (a `TaskTest`: the task's disturbance ``-w_t``, applied
while the object moves on a free, revolute or prismatic joint).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

__all__ = ["EvalConfig", "EvalError", "TaskTest", "DIRECTIONS", "DIRECTION_NAMES", "DEFAULT_TASKS"]

# The six test directions, in the order they are reported (and break ties between failures).
DIRECTION_NAMES: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")
DIRECTIONS: tuple[tuple[float, float, float], ...] = (
    (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
JOINT_KINDS = ("free", "hinge", "slide")


class EvalError(ValueError):
    """A configuration or input problem of the evaluation (not a failed grasp, which is a status).

    The message names the thing, the reason and, where possible, the remedy."""

    def __init__(self, thing: str, reason: str, remedy: str = "") -> None:
        self.thing, self.reason, self.remedy = thing, reason, remedy
        super().__init__(f"{thing}: {reason}" + (f" ({remedy})" if remedy else ""))


def _check(ok: bool, what: str, reason: str) -> None:
    if not ok:
        raise EvalError(what, reason)


def _unit3(v: Any, what: str) -> tuple[float, float, float]:
    t = tuple(float(x) for x in v)
    _check(len(t) == 3 and all(math.isfinite(x) for x in t), what, f"must be 3 finite numbers, got {v!r}")
    n = math.sqrt(sum(x * x for x in t))
    _check(n > 1e-9, what, "must be a non-zero direction")
    return tuple(x / n for x in t)  # type: ignore[return-value]


@dataclass(frozen=True)
class TaskTest:
    """The physical test of one task (object frame).

    The disturbance is ``-w_t`` (unit 6-D [force, torque] after normalization): its force part
    is scaled by ``force_n`` newtons (None: ``EvalConfig.force_per_kg * object mass``), its
    torque part by ``torque_nm`` N m, or if that is None by the force times ``torque_arm``
    object scales (a torque of F * arm * scale N m). The object moves on ``joint``: ``free``
    (6 DoF), ``hinge`` (revolute about ``axis`` through ``anchor``) or ``slide`` (prismatic
    along ``axis``); ``anchor`` is in metres; ``limits``: the joint's end stops from the initial
    pose, ``(lower, upper)`` metres or radians, None for a free side (None: no end stops).
    Success: the object stays within ``max_translation_m`` / ``max_rotation_deg`` (None: the `EvalConfig`'s), measured from the
    object's initial pose (``measure_from: initial``, as the six-direction protocol) or from its
    pose once the hand has closed (``closed``: only the disturbance's effect counts, as in the
    paper's task test where the hand is fixed at the grasp); ``min_touching_links`` (None: the
    config's) overrides the no-contact rule (a one-finger press touches one link).
    """

    w_t: tuple[float, float, float, float, float, float]
    joint: str = "free"
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    anchor: tuple[float, float, float] = (0.0, 0.0, 0.0)
    limits: tuple[float | None, float | None] | None = None
    force_n: float | None = None
    torque_arm: float = 1.0
    torque_nm: float | None = None
    max_translation_m: float | None = None
    max_rotation_deg: float | None = None
    min_touching_links: int | None = None
    measure_from: str = "initial"

    def __post_init__(self) -> None:
        w = tuple(float(x) for x in self.w_t)
        _check(len(w) == 6 and all(math.isfinite(x) for x in w), "TaskTest.w_t",
               f"must be 6 finite numbers, got {self.w_t!r}")
        _check(any(abs(x) > 0 for x in w), "TaskTest.w_t", "must be a non-zero wrench direction")
        object.__setattr__(self, "w_t", w)
        _check(self.joint in JOINT_KINDS, "TaskTest.joint", f"must be one of {JOINT_KINDS}, got {self.joint!r}")
        object.__setattr__(self, "axis", _unit3(self.axis, "TaskTest.axis"))
        a = tuple(float(x) for x in self.anchor)
        _check(len(a) == 3 and all(math.isfinite(x) for x in a), "TaskTest.anchor", "must be 3 finite numbers")
        object.__setattr__(self, "anchor", a)
        if self.limits is not None:
            ok = isinstance(self.limits, (tuple, list)) and len(self.limits) == 2 and self.joint != "free"
            lim = tuple(None if x is None else float(x) for x in self.limits) if ok else ()
            ok = ok and all(x is None or math.isfinite(x) for x in lim) \
                and (lim[0] is None or lim[0] <= 0) and (lim[1] is None or lim[1] >= 0) and lim != (None, None)
            _check(ok, "TaskTest.limits", "must be (lower <= 0, upper >= 0) of a hinge or slide joint, "
                   f"null for a side without an end stop; got {self.limits!r} on a {self.joint!r} joint")
            object.__setattr__(self, "limits", lim)
        _check(self.force_n is None or self.force_n > 0, "TaskTest.force_n", "must be > 0 or null")
        _check(self.torque_arm >= 0, "TaskTest.torque_arm", "must be >= 0")
        for name in ("torque_nm", "max_translation_m", "max_rotation_deg"):
            v = getattr(self, name)
            _check(v is None or (isinstance(v, (int, float)) and v > 0), f"TaskTest.{name}", f"must be > 0 or null, got {v!r}")
        _check(self.measure_from in ("initial", "closed"), "TaskTest.measure_from",
               f"must be 'initial' or 'closed', got {self.measure_from!r}")
        _check(self.min_touching_links is None or (isinstance(self.min_touching_links, int) and self.min_touching_links >= 0),
               "TaskTest.min_touching_links", f"must be an int >= 0 or null, got {self.min_touching_links!r}")

    def disturbance(self, object_mass_kg: float, object_scale_m: float, force_per_kg: float):
        """(6,) disturbance wrench [force N, torque N m] applied at the object's centre of mass."""
        import numpy as np

        w = -np.asarray(self.w_t, dtype=np.float64)
        w /= np.linalg.norm(w)
        f = self.force_n if self.force_n is not None else force_per_kg * object_mass_kg
        tau = self.torque_nm if self.torque_nm is not None else f * self.torque_arm * object_scale_m
        return np.concatenate([w[:3] * f, w[3:] * tau])


# Generic tests for any object (a knob turned about the object's z axis through its origin;
# lifting along +z). The benchmark's ten tasks (turn_handle, push_button, pull_drawer, ...) are
# not here: their tests come from their task YAMLs (`datagen.eval.tasks`), which `task_test`
# consults for any name not in `hold_tasks` or `tasks`.
DEFAULT_TASKS: dict[str, TaskTest] = {
    "turn_knob": TaskTest(w_t=(0, 0, 0, 0, 0, 1), joint="hinge", axis=(0, 0, 1)),
    "lift": TaskTest(w_t=(0, 0, 1, 0, 0, 0), joint="free"),
}


@dataclass(frozen=True)
class EvalConfig:
    """All constants of the evaluation (defaults: the public protocol of NOTES §3)."""

    # --- physics (MuJoCo options; gravity off) ---
    timestep_s: float = 0.004
    integrator: str = "implicitfast"
    cone: str = "elliptic"
    impratio: float = 10.0
    noslip_iterations: int = 2
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # --- contacts: set on every geom of the scene (hand and object) ---
    condim: int = 4
    friction: tuple[float, float] = (0.6, 0.02)   # sliding, torsional (rolling stays 1e-4)
    geom_margin_m: float = 0.0                     # the hand MJCFs' own margins are overridden
    hand_solimp: tuple[float, float, float] = (0.5, 0.99, 1e-4)
    hand_solref: tuple[float, float] = (0.005, 1.0)
    # --- hand control: every position actuator gets this gain and force limit ---
    actuator_kp: float = 5.0                       # the gymnasium-robotics Shadow has kp 1
    actuator_force_limit: float = 3.0              # N or N m, symmetric
    actuator_time_constant_s: float = 0.1          # actuator damping kv <= kp * this (Shadow: kv 0)
    weld_solref: tuple[float, float] = (0.02, 1.0)  # mocap-to-hand-root weld (MuJoCo default)
    # --- object ---
    object_mass_kg: float = 0.1                    # split over the pieces by volume
    # --- grasp execution: pregrasp -> grasp -> squeeze ---
    waypoints: int = 10                            # per phase (0.4 s each at the defaults)
    steps_per_waypoint: int = 10
    # --- hold test ---
    force_per_kg: float = 10.0                     # force = 10 * mass (1 N for 0.1 kg)
    hold_steps: int = 500                          # 2.0 s
    check_every: int = 50                          # steps between pose checks
    max_translation_m: float = 0.05
    max_rotation_deg: float = 15.0
    stop_at_first_failure: bool = True             # stop every direction at the first failing check
    threads: int = 1                               # >1: directions stepped by a thread pool
    # --- rejections before simulating and static metrics at the grasp pose ---
    max_pregrasp_penetration_m: float = 0.01       # deeper hand-object contact at the pregrasp: rejected
    # A hand link "touches" within touch_distance_m of the object at the grasp pose; fewer than
    # min_touching_links touching links -> no_contact (the squeeze alone must not make the grasp).
    # 5 mm, not 0: synthesis sees the hand as collision spheres that overshoot MuJoCo's collision
    # geoms by up to ~3 mm (Shadow spec: sphere_fit.overshoot 2.8 mm), so its touching fingertips
    # are 1-3 mm away from the object in MuJoCo.
    touch_distance_m: float = 0.005
    min_touching_links: int = 2
    contact_distance_m: float = 0.005              # hand geoms this close give the epsilon's contacts
    epsilon_mu: float | None = None                # None: friction[0]
    epsilon_samples: int = 1024                    # see datagen.wrench.EpsilonSearch
    epsilon_iters: int = 100
    # --- optional filters (None: off; the public protocol has none) ---
    filter_max_penetration_m: float | None = None  # hand-object depth at the grasp pose
    filter_max_self_penetration_m: float | None = None
    filter_min_epsilon: float | None = None
    # --- tasks ---
    hold_tasks: tuple[str, ...] = ("force_closure",)
    tasks: Mapping[str, TaskTest] = field(default_factory=lambda: dict(DEFAULT_TASKS))

    def __post_init__(self) -> None:
        c = "EvalConfig"
        _check(self.timestep_s > 0, f"{c}.timestep_s", "must be > 0")
        _check(self.integrator in ("euler", "rk4", "implicit", "implicitfast"), f"{c}.integrator",
               f"unknown integrator {self.integrator!r}")
        _check(self.cone in ("pyramidal", "elliptic"), f"{c}.cone", f"unknown cone {self.cone!r}")
        _check(self.impratio >= 1, f"{c}.impratio", "must be >= 1")
        _check(self.noslip_iterations >= 0, f"{c}.noslip_iterations", "must be >= 0")
        _check(self.condim in (1, 3, 4, 6), f"{c}.condim", "must be 1, 3, 4 or 6")
        _check(len(self.friction) == 2 and min(self.friction) >= 0, f"{c}.friction", "two values >= 0")
        _check(len(self.hand_solimp) == 3 and len(self.hand_solref) == 2, f"{c}.hand_solimp/solref", "3 and 2 values")
        for name in ("actuator_kp", "actuator_force_limit", "actuator_time_constant_s", "object_mass_kg",
                     "force_per_kg", "max_translation_m", "max_rotation_deg", "max_pregrasp_penetration_m", "touch_distance_m"):
            _check(getattr(self, name) > 0, f"{c}.{name}", f"must be > 0, got {getattr(self, name)}")
        _check(self.contact_distance_m >= self.touch_distance_m, f"{c}.contact_distance_m",
               "must be >= touch_distance_m")
        for name in ("waypoints", "steps_per_waypoint", "hold_steps", "check_every", "threads",
                     "epsilon_samples"):
            _check(int(getattr(self, name)) >= 1, f"{c}.{name}", "must be >= 1")
        _check(self.hold_steps % self.check_every == 0, f"{c}.hold_steps", "must be a multiple of check_every")
        _check(self.min_touching_links >= 0 and self.epsilon_iters >= 0, f"{c}.min_touching_links/epsilon_iters",
               "must be >= 0")
        tasks = {}
        for name, t in dict(self.tasks).items():
            tasks[str(name)] = t if isinstance(t, TaskTest) else TaskTest(**dict(t))
        overlap = set(tasks) & set(self.hold_tasks)
        _check(not overlap, f"{c}.tasks", f"{sorted(overlap)} are also hold_tasks")
        object.__setattr__(self, "tasks", tasks)
        object.__setattr__(self, "hold_tasks", tuple(self.hold_tasks))

    @property
    def hold_seconds(self) -> float:
        return self.hold_steps * self.timestep_s

    def task_test(self, task: str) -> TaskTest | None:
        """None for a six-direction task, else its `TaskTest`; unknown tasks raise `EvalError`.

        Looked up in ``hold_tasks``, then ``tasks``, then the built-in task YAMLs' ``eval`` block
        (`datagen.eval.tasks.builtin_task_test`)."""
        if task in self.hold_tasks:
            return None
        if task in self.tasks:
            return self.tasks[task]
        from .tasks import builtin_task_test, has_builtin_test

        if has_builtin_test(task):
            return builtin_task_test(task)
        raise EvalError(f"task {task!r}", "has no evaluation test",
                        f"known: {sorted(self.hold_tasks) + sorted(self.tasks)} and the built-in task YAMLs; "
                        "add it under `tasks` in the config")

    # ------------------------------------------------------------------ YAML
    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None) -> "EvalConfig":
        """Build from a mapping (e.g. YAML); unknown keys raise `EvalError`. ``tasks`` entries are
        mappings of `TaskTest` fields and extend (or replace, by name) the built-in tasks."""
        data = dict(data or {})
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise EvalError("eval config", f"unknown keys {unknown}", f"allowed: {sorted(known)}")
        if "tasks" in data:
            tasks = dict(DEFAULT_TASKS)
            for name, t in dict(data["tasks"] or {}).items():
                try:
                    tasks[str(name)] = TaskTest(**dict(t))
                except TypeError as exc:
                    raise EvalError(f"eval config task {name!r}", str(exc)) from None
            data["tasks"] = tasks
        for k in ("gravity", "friction", "hand_solimp", "hand_solref", "weld_solref", "hold_tasks"):
            if k in data:
                data[k] = tuple(data[k])
        return cls(**data)

    @classmethod
    def from_yaml(cls, path: str | Path) -> "EvalConfig":
        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise EvalError(str(path), f"cannot read the eval config: {exc}") from None
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out["tasks"] = {k: dataclasses.asdict(v) for k, v in self.tasks.items()}
        return out
