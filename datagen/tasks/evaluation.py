"""A task's physical test, from its YAML's ``eval`` block: the one source of each task's evaluation.

A task YAML carries, next to what synthesis reads (``w_t``, ``gamma_deg``, ``fingers``,
``init``), an ``eval`` entry: either the string ``six_direction`` (the six-direction hold test,
`datagen.eval.EvalConfig`) or a mapping::

    eval:
      test: task              # "task": the disturbance -w_t on the object's virtual joint,
                              # or "six_direction" (precision grasps)
      object: knob3           # a datagen.objects.task_objects name: the joint (kind, axis,
                              # anchor in metres) comes from the object, never re-typed here
      force_n: 1.5            # force magnitude of -w_t, N (null: EvalConfig.force_per_kg * mass)
      torque_nm: 0.05         # torque magnitude of -w_t, N m
      max_translation_m: 0.01 # pass thresholds (null: the EvalConfig's)
      max_rotation_deg: 10
      min_touching_links: 1   # no-contact rule override (one-finger press)
      measure_from: closed    # motion measured from the object's pose once the hand has closed

The test's ``w_t`` is the task's (and a row's own ``w_t`` replaces it at evaluation time).
`TaskTest` is the parsed test; `datagen.eval` runs it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from datagen.config import Config
from datagen.errors import EvalError

from .spec import TaskSpec, builtin_tasks, load_task

__all__ = ["EVAL_KEYS", "JOINT_KINDS", "TaskTest", "builtin_task_test", "has_builtin_test", "task_object", "task_scenery",
           "task_test_from_spec"]

JOINT_KINDS = ("free", "hinge", "slide")
EVAL_KEYS = ("test", "object", "force_n", "torque_nm", "torque_arm", "max_translation_m", "max_rotation_deg",
             "min_touching_links", "measure_from")
_TESTS = ("task", "six_direction")


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
class TaskTest(Config):
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
    config's) overrides the no-contact rule (a one-finger press touches one link). ``scenery``:
    static boxes ``((lo, hi), ...)`` (metres, object frame) round a mounted part (a door, a
    panel, a housing, a cabinet: the task object's ``scenery_m``): they collide with the hand,
    not with the object, and a hand inside them counts as penetration.
    """

    config_error: ClassVar[type[EvalError]] = EvalError

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
    scenery: tuple = ()

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
        boxes = []
        for box in self.scenery or ():
            try:
                lo, hi = (tuple(float(x) for x in v) for v in box)
                ok = len(lo) == len(hi) == 3 and all(math.isfinite(x) for x in lo + hi) and all(a < b for a, b in zip(lo, hi))
            except (TypeError, ValueError):
                ok = False
            _check(ok, "TaskTest.scenery", f"each box must be (lo, hi), 3 finite numbers each, lo < hi; got {box!r}")
            boxes.append((lo, hi))
        object.__setattr__(self, "scenery", tuple(boxes))
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


def _eval_block(spec: TaskSpec, where: str) -> dict[str, Any]:
    block = spec.eval
    if isinstance(block, str):
        block = {"test": block}
    if not isinstance(block, dict):
        raise EvalError(f"{where}: eval", f"must be 'six_direction' or a mapping, got {block!r}")
    unknown = sorted(set(block) - set(EVAL_KEYS))
    if unknown:
        raise EvalError(f"{where}: eval", f"unknown field(s) {unknown}", f"known: {list(EVAL_KEYS)}")
    test = block.get("test", "task")
    if test not in _TESTS:
        raise EvalError(f"{where}: eval.test", f"must be one of {list(_TESTS)}, got {test!r}")
    return dict(block, test=test)


def task_object(spec: TaskSpec) -> str | None:
    """The task object name a spec's ``eval.object`` names (None if it names none)."""
    block = spec.eval if isinstance(spec.eval, dict) else {}
    return block.get("object")


def task_test_from_spec(spec: TaskSpec, where: str | None = None) -> TaskTest | None:
    """The `TaskTest` of a loaded `TaskSpec` (None: the six-direction test)."""
    from datagen.objects import task_objects  # trimesh/manifold: only when a test is built

    where = where or f"task {spec.name!r}"
    block = _eval_block(spec, where)
    name = block.get("object")
    if name is not None and name not in task_objects.TASK_OBJECTS:
        raise EvalError(f"{where}: eval.object", f"unknown task object {name!r}", f"known: {list(task_objects.TASK_OBJECTS)}")
    if block["test"] == "six_direction":
        return None
    if name is None:
        raise EvalError(f"{where}: eval.object", "a task test needs the object whose virtual joint it moves on",
                        f"one of {list(task_objects.TASK_OBJECTS)}")
    obj = task_objects.build(name)
    joint = obj.joint
    kw = {k: block[k] for k in EVAL_KEYS[2:] if k in block and block[k] is not None}
    try:
        return TaskTest(w_t=tuple(spec.w_t), joint=joint.kind, axis=joint.axis, anchor=joint.anchor_m,
                        limits=joint.limits, scenery=obj.scenery_m, **kw)
    except EvalError as exc:
        raise EvalError(f"{where}: eval ({exc.thing})", exc.reason, exc.remedy) from None


def task_scenery(spec: TaskSpec) -> tuple:
    """The static boxes ``((lo (3,), hi (3,)), ...)`` (metres, object frame) the hand must stay out
    of for ``spec``: its test's ``scenery`` (the task object's), () for a six-direction test or a
    task bound to no object. Synthesis and evaluation read the same boxes."""
    if task_object(spec) is None:
        return ()
    test = task_test_from_spec(spec)
    return () if test is None else test.scenery


@functools.lru_cache(maxsize=None)
def has_builtin_test(task: str) -> bool:
    """Whether ``task`` is a built-in task YAML (``datagen/tasks/specs/<task>.yaml``)."""
    return task in builtin_tasks()


@functools.lru_cache(maxsize=None)
def builtin_task_test(task: str) -> TaskTest | None:
    """The test of built-in task ``task`` from its YAML (cached; None: six directions)."""
    return task_test_from_spec(load_task(task), where=f"task YAML {task!r}")
