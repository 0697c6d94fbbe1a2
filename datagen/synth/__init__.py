"""Grasp synthesis: energies, initialization, optimizer (paper Sec. IV-C); tasks come from `datagen.tasks`.

    hand = load_hand("shadow")
    target = GraspTarget.from_processed(process_object(ref), scale=0.08)
    result = synthesize(hand, [target], load_task("force_closure"), SynthConfig(), num_per_object=100)
"""

from datagen.synth.config import ConfigError, EnergyWeights, SynthConfig
from datagen.synth.synthesize import SynthesisResult, synthesize
from datagen.synth.target import GraspTarget

__all__ = [
    "ConfigError",
    "EnergyWeights",
    "GraspTarget",
    "SynthConfig",
    "SynthesisResult",
    "synthesize",
]
