"""The per-object pipeline in one place: processed objects -> synthesis targets -> synthesis ->
rows -> MuJoCo evaluation -> evaluated rows (`run_batch`), and its stages for front ends that
stop early or swap one (`build_targets`, `synthesize_rows`, `evaluate_rows`).

Its configuration is one resolved `Recipe` per hand and task (`resolve`: library defaults ->
preset -> task YAML -> the user's config -> flags); `synthesize` is the five-line library call
(a mesh path to evaluated rows). Pure: no Ray, no job directory, no files written. Used by the job workers (`workers.shard`), the
``datagen synth`` command (`commands`) and the benchmarks. Sits above `datagen.synth`,
`datagen.eval` and `datagen.tasks`, below the command line and the workers.
"""

from .api import load_object, synthesize
from .batch import BatchObject, BatchResult, build_targets, evaluate_rows, failure, run_batch, synthesize_rows
from .recipe import DEFAULT_PRESET, PRESETS, Recipe, resolve

__all__ = ["BatchObject", "BatchResult", "DEFAULT_PRESET", "PRESETS", "Recipe", "build_targets", "evaluate_rows",
           "failure", "load_object", "resolve", "run_batch", "synthesize", "synthesize_rows"]
