"""MuJoCo evaluation of grasps: six-direction hold test, task test, penetration and epsilon.

    from datagen.eval import EvalConfig, Evaluator, pieces_from_processed
    with Evaluator(load_hand("shadow"), EvalConfig()) as ev:
        result = ev.evaluate(pieces_from_processed(obj, 0.06), poses, task="force_closure")

``poses`` (3, 7 + J): pregrasp, grasp, squeeze rows [x y z qw qx qy qz, joints] in the object
frame (metres, radians). `GraspResult` carries ``success``, a ``reason`` code (`Reason`) and the
metrics; ``Evaluator.margin`` also the largest multiple of the test's disturbance the grasp holds
(`TaskMargin`). ``datagen eval`` (table.py, commands.py) adds them as columns to a grasp table;
``datagen render`` draws grasps (render.py).

The names below are loaded on first use: importing ``datagen.eval`` (or its CLI module) does not
import mujoco, so a rendering command can choose ``MUJOCO_GL`` first (`datagen.gl`).
"""

from __future__ import annotations

import importlib

__all__ = [
    "DEFAULT_TASKS", "DIRECTION_NAMES", "EvalConfig", "EvalError", "Evaluator", "GraspResult",
    "MULTIPLES", "OCTAVE_MULTIPLES", "ObjectPieces", "Reason", "Scene", "TaskMargin", "TaskTest", "build_scene",
    "pieces_from_processed",
]
_MODULE = {"DEFAULT_TASKS": "config", "DIRECTION_NAMES": "config", "EvalConfig": "config", "EvalError": "config",
           "TaskTest": "config", "Evaluator": "evaluate", "GraspResult": "evaluate", "Reason": "evaluate",
           "MULTIPLES": "evaluate", "OCTAVE_MULTIPLES": "evaluate", "TaskMargin": "evaluate",
           "ObjectPieces": "scene", "Scene": "scene", "build_scene": "scene", "pieces_from_processed": "scene"}


def __getattr__(name: str):
    if name not in _MODULE:
        raise AttributeError(f"module 'datagen.eval' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_MODULE[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
