"""Tasks as data, below synthesis and evaluation (both read them; neither imports the other).

    spec = load_task("turn_knob2")          # datagen/tasks/specs/turn_knob2.yaml, or a YAML path
    spec.w_t, spec.gamma_deg, spec.fingers  # the task wrench space and contact fingertips (synthesis)
    spec.init                               # InitConfig: the initial hand poses (datagen.synth.init)
    spec.for_hand("allegro")                # the task with its `hands:` entry for that hand applied
    spec.synth                              # its `synth:` block (a layer of datagen.pipeline.resolve)
    task_test_from_spec(spec)               # TaskTest: the physical test (datagen.eval), None: six directions
    task_scenery(spec)                      # static boxes round a mounted object (door, housing, cabinet)
    task_targets(spec, targets)             # the objects it runs on
    load_grasp_type("power")                # GraspType: a force-closure grasp's contact set (grasp_types/)

Modules: ``spec`` (TaskSpec, InitConfig, loading), ``evaluation`` (the ``eval`` block, TaskTest),
``pairing`` (task/object pairing), ``grasp_type`` (grasp types and the per-size mix). Depends only on `datagen.config`, `datagen.errors` and
`datagen.objects.task_objects`.
"""

from .evaluation import (EVAL_KEYS, TaskTest, builtin_task_test, has_builtin_test, task_object, task_scenery,
                         task_test_from_spec)
from .grasp_type import FlatBand, GraspBand, GraspMix, GraspType, GraspTypeHand, builtin_grasp_types, load_grasp_type
from .pairing import task_object_id, task_targets
from .spec import SPEC_DIR, HandOverride, InitConfig, TaskSpec, builtin_tasks, load_task

__all__ = [
    "EVAL_KEYS", "SPEC_DIR", "FlatBand", "GraspBand", "GraspMix", "GraspType", "GraspTypeHand", "HandOverride", "InitConfig", "TaskSpec", "TaskTest", "builtin_grasp_types", "builtin_task_test", "builtin_tasks",
    "has_builtin_test", "load_grasp_type", "load_task", "task_object", "task_object_id", "task_scenery", "task_targets",
    "task_test_from_spec",
]
