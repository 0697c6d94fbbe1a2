"""MuJoCo evaluation of grasps: six-direction hold test, task test, penetration and epsilon.

    from datagen.eval import EvalConfig, Evaluator, pieces_from_processed
    with Evaluator(load_hand("shadow"), EvalConfig()) as ev:
        result = ev.evaluate(pieces_from_processed(obj, 0.06), poses, task="force_closure")

``poses`` (3, 7 + J): pregrasp, grasp, squeeze rows [x y z qw qx qy qz, joints] in the object
frame (metres, radians). `GraspResult` carries ``success``, a ``reason`` code (`Reason`) and the
metrics. ``datagen eval`` (table.py, commands.py) adds them as columns to a grasp table;
``datagen render`` draws grasps (render.py).
"""

from .config import DEFAULT_TASKS, DIRECTION_NAMES, EvalConfig, EvalError, TaskTest
from .evaluate import Evaluator, GraspResult, Reason
from .scene import ObjectPieces, Scene, build_scene, pieces_from_processed

__all__ = [
    "DEFAULT_TASKS", "DIRECTION_NAMES", "EvalConfig", "EvalError", "Evaluator", "GraspResult",
    "ObjectPieces", "Reason", "Scene", "TaskTest", "build_scene", "pieces_from_processed",
]
