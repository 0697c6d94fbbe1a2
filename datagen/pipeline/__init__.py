"""The per-object pipeline in one place: processed objects -> synthesis targets -> synthesis ->
rows -> MuJoCo evaluation -> evaluated rows (`run_batch`), and its stages for front ends that
stop early or swap one (`build_targets`, `synthesize_rows`, `evaluate_rows`).

Pure: no Ray, no job directory, no files written. Used by the job workers (`workers.shard`), the
``datagen synth`` command (`commands`) and the benchmarks. Sits above `datagen.synth`,
`datagen.eval` and `datagen.tasks`, below the command line and the workers.
"""

from .batch import BatchObject, BatchResult, build_targets, evaluate_rows, failure, run_batch, synthesize_rows

__all__ = ["BatchObject", "BatchResult", "build_targets", "evaluate_rows", "failure", "run_batch",
           "synthesize_rows"]
