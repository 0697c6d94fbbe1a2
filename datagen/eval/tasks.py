"""Task tests from the task YAMLs: the one source of each task's evaluation.

A task YAML (``datagen/synth/tasks/<name>.yaml``) carries, next to what synthesis reads
(``w_t``, ``gamma_deg``, ``fingers``, ``init``), an ``eval`` entry: either the string
``six_direction`` (the hold test of NOTES §3) or a mapping::

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
"""

from __future__ import annotations

import functools
from typing import Any

from .config import EvalError, TaskTest

__all__ = ["EVAL_KEYS", "builtin_task_test", "has_builtin_test", "task_object", "task_test_from_spec"]

EVAL_KEYS = ("test", "object", "force_n", "torque_nm", "torque_arm", "max_translation_m", "max_rotation_deg",
             "min_touching_links", "measure_from")
_TESTS = ("task", "six_direction")


def _eval_block(spec, where: str) -> dict[str, Any]:
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


def task_object(spec) -> str | None:
    """The task object name a spec's ``eval.object`` names (None if it names none)."""
    block = spec.eval if isinstance(spec.eval, dict) else {}
    return block.get("object")


def task_test_from_spec(spec, where: str | None = None) -> TaskTest | None:
    """The `TaskTest` of a loaded `datagen.synth.TaskSpec` (None: the six-direction test)."""
    from datagen.objects import task_objects

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
    joint = task_objects.build(name).joint
    kw = {k: block[k] for k in EVAL_KEYS[2:] if k in block and block[k] is not None}
    try:
        return TaskTest(w_t=tuple(spec.w_t), joint=joint.kind, axis=joint.axis, anchor=joint.anchor_m,
                        limits=joint.limits, **kw)
    except EvalError as exc:
        raise EvalError(f"{where}: eval ({exc.thing})", exc.reason, exc.remedy) from None


@functools.lru_cache(maxsize=None)
def has_builtin_test(task: str) -> bool:
    """Whether ``task`` is a built-in task YAML (``datagen/synth/tasks/<task>.yaml``)."""
    from datagen.synth.config import builtin_tasks

    return task in builtin_tasks()


@functools.lru_cache(maxsize=None)
def builtin_task_test(task: str) -> TaskTest | None:
    """The test of built-in task ``task`` from its YAML (cached; None: six directions)."""
    from datagen.synth.config import load_task

    return task_test_from_spec(load_task(task), where=f"task YAML {task!r}")
