"""Grasp synthesis: energies, initialization, optimizer, tasks as data (paper Sec. IV-C).

    hand = load_hand("shadow")
    target = GraspTarget.from_processed(process_object(ref), scale=0.08)
    result = synthesize(hand, [target], load_task("force_closure"), SynthConfig(), num_per_object=100)
"""

from datagen.synth.config import ConfigError, EnergyWeights, InitConfig, SynthConfig, TaskSpec, builtin_tasks, load_task
from datagen.synth.synthesize import SynthesisResult, synthesize
from datagen.synth.target import GraspTarget

__all__ = [
    "ConfigError",
    "EnergyWeights",
    "GraspTarget",
    "InitConfig",
    "SynthConfig",
    "SynthesisResult",
    "TaskSpec",
    "builtin_tasks",
    "load_task",
    "synthesize",
]
