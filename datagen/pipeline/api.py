"""The five-line library call: a mesh path to evaluated rows, with the command line's grasps.

    import datagen
    rows = datagen.synthesize("shadow", "mug.obj", "force_closure", n=16)   # pyarrow Table
    ok = rows.filter(rows["success"])                                        # grasps that hold

`synthesize` resolves the recipe as ``datagen synth`` and ``datagen run`` do (`resolve`: the
``dataset`` preset unless told otherwise), processes the mesh through the objects cache (in a
child process with a time limit, as ``datagen prepare`` does), synthesizes ``n`` grasps per
scale in one batch and evaluates them in MuJoCo (`run_batch`). The same hand, mesh, task,
settings and seed give the rows of ``datagen synth`` followed by ``datagen eval``, and of a
one-object job (shard 0 synthesizes with the job's seed).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

__all__ = ["load_object", "synthesize"]


def load_object(path: str | Path, process, cache: str | Path | None = None):
    """The processed object (`datagen.objects.ProcessedObject`, status ok) of a raw mesh file,
    processed with ``process`` (a `ProcessConfig`: the recipe's) through the objects cache under
    ``cache`` in a child process (a Ctrl-C or a CoACD crash ends only that process), or of a
    processed-object directory (one holding ``meta.json``). Raises FileNotFoundError or
    ValueError naming the object and the reason."""
    from datagen.objects import layout
    from datagen.objects.isolate import process_isolated
    from datagen.objects.manifest import ManifestEntry
    from datagen.objects.prepare import DEFAULT_TIMEOUT_S
    from datagen.objects.process import load_processed
    from datagen.objects.sources import resolve as resolve_ref

    p = Path(path)
    if p.is_dir() and (p / layout.META).is_file():
        processed = load_processed(p)
    elif p.is_file():
        ref = resolve_ref(f"dir:{p.parent.resolve()}", p.name, p.stem)
        processed = process_isolated(ManifestEntry.of_ref(ref), process, cache, DEFAULT_TIMEOUT_S,
                                     remedy="process it first with `datagen prepare --timeout SECONDS`")
    else:
        raise FileNotFoundError(f"object {p} is neither a mesh file nor a processed-object directory")
    if not processed.ok:
        raise ValueError(f"object {p}: processing failed ({processed.reason}): {processed.message}")
    return processed


def synthesize(hand: str = "shadow", obj: str | Path = "", task: str | Path = "force_closure", *, n: int = 16,
               scales: Sequence[float] = (0.08,), seed: int | None = None, preset: str | None = None,
               config: Mapping[str, Any] | None = None, evaluate: bool = True, cache: str | Path | None = None,
               device: str = "cpu", scene: str | Mapping[str, Any] | None = None):
    """``n`` grasps per scale of ``hand`` on the mesh ``obj`` for ``task``, as a pyarrow Table:
    the ``evaluated`` schema's rows (MuJoCo verdict in ``success``), or with ``evaluate=False``
    the synthesized ``grasps`` rows. ``hand``, ``task``: built-in names or YAML paths; ``scales``:
    metres per normalized object unit; ``seed`` (None: the recipe's, 0); ``preset``/``config``:
    see `datagen.pipeline.resolve` (``config`` a mapping of ``synth``/``eval``/``process``/
    ``grasp_types``/``grid_resolution``/``scene`` settings); ``scene``: ``"floating"`` or ``"tabletop"``
    (or ``{"kind": "tabletop", "stable_poses": 2}``; None: the config's, floating; docs/scenes.md);
    ``cache``: the objects cache root (default $DATAGEN_CACHE).
    Failures of the object's target, synthesis or evaluation raise ValueError naming them."""
    from datagen.hands import load_hand

    from .batch import BatchObject, build_targets, run_batch, synthesize_rows
    from .recipe import resolve

    flags = {"synth": {"seed": int(seed)}} if seed is not None else {}
    if scene is not None:
        flags["scene"] = scene
    recipe = resolve(hand, task, preset=preset, config=config, flags=flags)
    model = load_hand(hand, device=device)
    objects = [BatchObject(load_object(obj, recipe.process, cache), tuple(scales))]
    if not evaluate:
        targets = build_targets(objects, grid_resolution=recipe.grid_resolution, cache=cache, device=device,
                                scene=recipe.scene)
        return synthesize_rows(model, targets, recipe.load_task(), recipe.synth, n, grasp_types=recipe.grasp_types,
                               type_synth=recipe.grasp_type_synth)[1]
    out = run_batch(objects, model, [recipe], grasps_per_object=n, cache=cache, device=device)
    if out.failures:
        raise ValueError("; ".join(f"{f['stage']}: {f['message']}" for f in out.failures))
    return out.rows
