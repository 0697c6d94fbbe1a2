"""datagen: a dataset factory for dexterous robot hands.

Data flows one way: manifest -> objects -> synthesis -> evaluation -> shards (ARCHITECTURE.md).
The names below are the curated API; each is imported from its package on first use, so
``import datagen`` stays light and has no side effects beyond a `logging.NullHandler`::

    import datagen
    rows = datagen.synthesize("shadow", "mug.obj", "force_closure", n=16)   # evaluated rows, the CLI's grasps
    recipe = datagen.resolve("shadow", "precision_key", flags={"synth": {"iters": 200}})  # one resolved config
    hand = datagen.load_hand("shadow")
    obj = datagen.process_object(ref, recipe.process)      # ref: datagen.objects.iter_source(...)
    rows = datagen.run_batch([datagen.BatchObject(obj, (0.08,))], hand, [recipe], grasps_per_object=16).rows
    with datagen.Evaluator(hand, recipe.eval) as ev: ...
    loader = torch.utils.data.DataLoader(datagen.GraspDataset("jobs/default"), batch_size=256)
"""

import importlib
import logging

__version__ = "0.1.0"

# Library diagnostics go to the "datagen" logger (modules log to its children, datagen.<module>);
# silent unless the application configures logging.
logging.getLogger("datagen").addHandler(logging.NullHandler())

_API = {
    "DatagenError": "datagen.errors", "ConfigError": "datagen.errors",
    "load_hand": "datagen.hands",
    "ObjectRef": "datagen.objects", "iter_source": "datagen.objects", "process_object": "datagen.objects",
    "TaskSpec": "datagen.tasks", "load_task": "datagen.tasks", "builtin_tasks": "datagen.tasks",
    "GraspTarget": "datagen.synth", "SynthConfig": "datagen.synth",
    "EvalConfig": "datagen.eval", "Evaluator": "datagen.eval", "pieces_from_processed": "datagen.eval",
    "GraspDataset": "datagen.io", "read_job": "datagen.io",
    "BatchObject": "datagen.pipeline", "run_batch": "datagen.pipeline", "synthesize": "datagen.pipeline",
    "Recipe": "datagen.pipeline", "resolve": "datagen.pipeline",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'datagen' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
