"""The per-object pipeline in one place: processed objects -> synthesis targets -> synthesis ->
rows -> MuJoCo evaluation -> evaluated rows (`run_batch`), and its stages for front ends that
stop early or swap one (`build_targets`, `synthesize_rows`, `evaluate_rows`).

Its configuration is one resolved `Recipe` per hand and task (`resolve`: library defaults ->
preset -> task YAML -> the user's config -> flags); `synthesize` is the five-line library call
(a mesh path to evaluated rows). Pure: no Ray, no job directory, no files written. Used by the job workers (`workers.shard`), the
``datagen synth`` command (`commands`) and the benchmarks. Sits above `datagen.synth`,
`datagen.eval` and `datagen.tasks`, below the command line and the workers.
"""

from importlib import import_module

_EXPORTS = {"load_object": "api", "synthesize": "api", "DEFAULT_PRESET": "recipe", "PRESETS": "recipe",
            "Recipe": "recipe", "resolve": "recipe", **{name: "batch" for name in (
                "BatchObject", "BatchResult", "build_targets", "evaluate_rows", "failure", "run_batch",
                "synthesize_rows")}}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    """The package's names, imported on first use: the command registrars in `commands` (imported
    by the command line before a path is checked) pull in no torch, pyarrow or MuJoCo."""
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
