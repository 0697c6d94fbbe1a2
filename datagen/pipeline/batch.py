"""The batch pipeline as one pure function: processed objects -> evaluated rows.

    objects = [BatchObject(process_object(ref, recipe.process), scales=(0.06, 0.08))]
    out = run_batch(objects, load_hand("shadow"), [resolve("shadow", "force_closure")],
                    grasps_per_object=8, seed=0)
    out.rows       # pyarrow Table of the `evaluated` schema (schemas/evaluated.json), no metadata
    out.failures   # one dict per failed object/stage: object_id, object_scale_m, task, stage, reason, message

Stages, each a function of its own so a front end can stop early (``datagen synth`` writes the
synthesized rows without evaluating them) or swap one (a benchmark executing other squeezes):

1. `build_targets`: one `GraspTarget` per object and scale (and, for a tabletop scene, per stable
   pose: `datagen.objects.tabletop`). The SDF and its grid are in normalized units, so they are
   built once per object (at its first scale) and the hull samples are rescaled for the other scales.
2. per recipe (one per task, `datagen.pipeline.resolve`; its objects paired by
   `datagen.tasks.task_targets`): `synthesize_rows`, one batch for every target of the task and
   grasp type (the recipe's ``grasp_types`` by object size), seeded by ``seed``; rows of the
   ``grasps`` schema.
3. `evaluate_rows`: the MuJoCo test, per object and scale, so one bad object costs only its rows.

Anything that fails for an object (its target, the batch's synthesis, its evaluation) becomes a
failure record with the stage and the reason, never an exception (an unknown task name still
raises, as it is found). No Ray,
no job directory, no writing: `workers.shard` processes the objects (isolated, time-limited),
calls `run_batch` and writes the shard. Same inputs and seed, same rows.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import pyarrow as pa
import pyarrow.compute as pc

from schemas import arrow_schema

__all__ = ["BatchObject", "BatchResult", "build_targets", "evaluate_rows", "failure", "run_batch",
           "synthesize_rows"]

#: ``progress(done, total)``: work units done so far and in all (see `run_batch`)
Progress = Callable[[float, float], None]


@dataclass(frozen=True)
class BatchObject:
    """A processed object (``datagen.objects.ProcessedObject``, status ok) and the scales (metres
    per normalized unit) it is synthesized at. What the rows record of it defaults to the
    processed object's own: ``object_id``, ``object_path`` (its cache entry; a job passes the
    path relative to the job directory, the evaluation's ``base``), ``mesh_sha256``; ``split``:
    the manifest split ("" when there is none)."""

    processed: object
    scales: tuple[float, ...]
    object_id: str = ""
    object_path: str = ""
    mesh_sha256: str = ""
    split: str = ""

    def __post_init__(self):
        p = self.processed
        object.__setattr__(self, "scales", tuple(float(s) for s in self.scales))
        if not self.scales:
            raise ValueError(f"object {self.object_id or p.object_id}: no scales to synthesize at")
        object.__setattr__(self, "object_id", self.object_id or p.object_id)
        object.__setattr__(self, "object_path", self.object_path or (str(p.entry) if p.entry else ""))
        object.__setattr__(self, "mesh_sha256", self.mesh_sha256 or p.mesh_sha256)


@dataclass
class BatchResult:
    """What `run_batch` returns: the evaluated rows (``evaluated`` schema without metadata, in
    task, object, scale, grasp order), the failure records and seconds per stage
    (``target_s``, ``synth_s``, ``eval_s``)."""

    rows: pa.Table
    failures: list[dict] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def failure(object_id: str, stage: str, reason: str, message: str, scale: float = float("nan"),
            task: str = "") -> dict:
    """A failure record (the ``failures`` schema's columns, less ``shard``)."""
    return {"object_id": object_id, "object_scale_m": scale, "task": task, "stage": stage,
            "reason": reason or "error", "message": message}


def build_targets(objects: Sequence[BatchObject], *, grid_resolution: int | None = None,
                  cache: str | Path | None = None, device: str = "cpu", failures: list | None = None,
                  progress: Callable[[], None] | None = None, scene=None) -> list:
    """One `GraspTarget` per object and scale (in order); with ``scene`` tabletop (a
    `datagen.objects.tabletop.SceneConfig`; None: floating) one per object, scale and stable
    pose, the object resting on the table (`GraspTarget.on_table`). The SDF and its grid are built once per
    object at its first scale (grids from the grid cache under ``cache``; ``grid_resolution``
    nodes per axis, None: `GraspTarget`'s default); the other scales rescale its hull samples.
    An object whose target cannot be built is appended to ``failures`` (stage ``target``) and
    skipped; with ``failures=None`` it raises ValueError naming the object and the cause. ``progress()`` is called once per object."""
    from datagen.synth import GraspTarget

    kw = {} if grid_resolution is None else {"grid_resolution": grid_resolution}
    targets = []
    for o in objects:
        try:
            base = GraspTarget.from_processed(o.processed, o.scales[0], cache=cache, **kw)
            poses = _stable_poses(base, scene)
        except Exception as exc:  # noqa: BLE001 - recorded, never fatal
            message = f"{o.object_id}: {type(exc).__name__}: {exc}"
            if failures is None:
                raise ValueError(f"cannot build the synthesis target of {message}") from exc
            failures.append(failure(o.object_id, "target", "error", message))
            continue
        finally:
            if progress is not None:
                progress()
        for s in o.scales:
            # the id and hash are the caller's: the processed object may be a cache entry made for
            # another object with the same bytes (its meta names that one)
            t = dataclasses.replace(base, object_id=o.object_id, scale=float(s),
                                    hull_points=base.hull_points * (s / base.scale), object_path=o.object_path,
                                    mesh_sha256=o.mesh_sha256)
            t = t.to(device) if device != "cpu" else t
            targets += [t] if poses is None else [t.on_table(p) for p in poses]
    return targets


def _stable_poses(target, scene) -> list | None:
    """The stable poses of a target's object (normalized units) for a tabletop ``scene``; None
    for a floating one."""
    if scene is None or not scene.tabletop:
        return None
    from datagen.objects.tabletop import stable_poses

    sdf = target.sdf
    return stable_poses(sdf.vertices.detach().cpu().double().numpy(), sdf.faces.cpu().numpy(),
                        target.centre_of_mass / target.scale, scene.stable_poses, target.object_id)


def synthesize_rows(hand, targets: Sequence, task, cfg, grasps_per_object: int, *, grasp_types=None,
                    type_synth: Mapping[str, Mapping] | None = None, splits: Mapping[str, str] | None = None,
                    callback=None):
    """``(results, table)``: ``grasps_per_object`` grasps on every target (`datagen.synth.synthesize`,
    seeded by ``cfg.seed``) and their rows (``grasps`` schema, `datagen.synth.rows.result_table`).
    ``cfg`` is the task's resolved `SynthConfig` (``resolve(...).synth``); ``grasp_types``: the
    recipe's `datagen.tasks.GraspMix` (None: ``cfg.grasp_type`` for every grasp), applied to a
    force-closure task on every fingertip: one batch per grasp type and grasp count (the targets
    in order, so one type gives the one batch of every target), ``results`` in that order; a
    type's batch synthesizes with ``type_synth``'s fields for it over ``cfg`` (the recipe's
    ``grasp_type_synth``: `datagen.pipeline.recipe.for_grasp_type`).
    ``callback(it, ...)`` is the optimizer's per-iteration hook."""
    from datagen.synth import synthesize
    from datagen.synth.rows import result_table

    from .recipe import for_grasp_type

    results, tables = [], []
    for name, count, group in _grasp_groups(task, targets, grasps_per_object, grasp_types, cfg.grasp_type):
        c = for_grasp_type(cfg, name, type_synth)
        result = synthesize(hand, group, task, c, count, callback=callback)
        results.append(result)
        tables.append(result_table(result, group, hand, task, c, splits=splits))
    return results, tables[0] if len(tables) == 1 else pa.concat_tables(tables)


def _grasp_groups(task, targets: Sequence, n: int, mix, default: str) -> list[tuple[str, int, list]]:
    """``[(grasp type, grasps per target, targets)]``: the batches `synthesize_rows` runs."""
    if mix is None or task.fingers != "all" or task.gamma_deg < 180:
        return [(default, n, list(targets))]
    groups: dict[tuple[str, int], list] = {}
    for t in targets:
        height = t.footprint.height if t.support_plane is not None else None
        for name, count in mix.counts(float(t.scale), n, height).items():
            groups.setdefault((name, count), []).append(t)
    return [(name, count, group) for (name, count), group in groups.items()]


def evaluate_rows(table: pa.Table, targets: Sequence, task_name: str, eval_cfg, *, base: str | Path = ".",
                  failures: list | None = None, progress: Callable[[], None] | None = None,
                  workers: int = 1, spare_cores: Callable[[], int] | None = None) -> list[pa.Table]:
    """The rows of ``table`` evaluated in MuJoCo (`datagen.eval.table.evaluate_table`), one
    table per target (object and scale) in ``targets`` order. A target whose evaluation raises is
    appended to ``failures`` (stage ``eval``; raised when ``failures`` is None) and its rows
    dropped. ``progress()`` is called once per target. ``workers`` > 1: the rows of all targets
    go to one pool of that many processes (the verdicts are the same as with one); if that
    raises, each target is evaluated on its own to find the one that fails. ``spare_cores``: see
    `datagen.eval.Evaluator` (with one worker, a grasp may use a core that sits idle)."""
    from datagen.eval.table import evaluate_table

    def rows_of(tb: pa.Table, t) -> pa.Table:
        same = pc.and_(pc.equal(tb["object_id"], t.object_id),
                       pc.equal(tb["object_scale_m"], pa.scalar(t.scale, pa.float32())))
        if "stable_pose" in tb.column_names:  # one stable pose's rows (all -1 when floating)
            same = pc.and_(same, pc.equal(tb["stable_pose"], pa.scalar(t.stable_pose, pa.int32())))
        return tb.filter(same)

    if workers > 1 and len(targets) > 1:
        try:
            whole = evaluate_table(table, eval_cfg, base=base, workers=workers)
        except Exception:  # noqa: BLE001 - found and recorded per target below
            pass
        else:
            out = []
            for t in targets:
                if progress is not None:
                    progress()
                out.append(rows_of(whole, t))
            return out
    out = []
    evaluators: dict = {}  # one hand load for every target (0.3 s each on Shadow, 2 cores)
    try:
        for t in targets:
            if progress is not None:
                progress()
            try:
                out.append(evaluate_table(rows_of(table, t), eval_cfg, base=base, workers=workers,
                                          spare_cores=spare_cores, evaluators=evaluators))
            except Exception as exc:  # noqa: BLE001
                if failures is None:
                    raise
                failures.append(failure(t.object_id, "eval", "error", f"{t.object_id} at {t.scale} m, task "
                                        f"{task_name}: {type(exc).__name__}: {exc}", t.scale, task_name))
    finally:
        for ev in evaluators.values():
            ev.close()
    return out


def run_batch(objects: Sequence[BatchObject], hand, recipes: Sequence, *, grasps_per_object: int,
              seed: int | None = None, cache: str | Path | None = None, base: str | Path = ".", device: str = "cpu",
              progress: Progress | None = None, eval_workers: int = 1,
              eval_spare_cores: Callable[[], int] | None = None) -> BatchResult:
    """Processed objects -> evaluated rows (see the module docstring).

    ``hand``: a `datagen.hands.HandModel` on ``device``; ``recipes``: one resolved `Recipe` per
    task (`datagen.pipeline.resolve`, same hand and grid resolution), each synthesizing with its
    ``synth`` (seed replaced by ``seed`` when given) and evaluating with its ``eval``;
    ``grasps_per_object`` per object and scale; ``cache``: see `build_targets`; ``base``: the
    directory the objects' ``object_path`` values are relative to; ``eval_workers``: processes
    for the MuJoCo tests and ``eval_spare_cores`` (`evaluate_rows`). ``progress(done, total)``
    in work units: one per object's target, then per task as many for its synthesis (moving with
    its iterations) and as many again for its evaluation as there are objects x scales."""
    timings = {"target_s": 0.0, "synth_s": 0.0, "eval_s": 0.0}
    fails: list[dict] = []
    grid, scene = _shared(recipes, "grid_resolution"), _shared(recipes, "scene")
    n_targets = sum(len(o.scales) for o in objects)
    units = _Units(progress, len(objects) + 2 * len(recipes) * n_targets)
    t0 = time.perf_counter()
    all_targets = build_targets(objects, grid_resolution=grid, cache=cache, device=device, failures=fails,
                                progress=lambda: units.add(1), scene=scene)
    timings["target_s"] = time.perf_counter() - t0
    units.set(len(objects))
    splits = {o.object_id: o.split for o in objects}
    tables: list[pa.Table] = []
    for k, recipe in enumerate(recipes):
        units.set(len(objects) + 2 * k * n_targets)
        tables += _run_recipe(hand, recipe, all_targets, units, n_targets, fails, timings, seed=seed,
                              grasps_per_object=grasps_per_object, splits=splits, base=base,
                              eval_workers=eval_workers, eval_spare_cores=eval_spare_cores)
    schema = arrow_schema("evaluated", nq=7 + hand.num_joints).remove_metadata()
    rows = (pa.concat_tables([tb.select(schema.names).cast(schema) for tb in tables]) if tables
            else schema.empty_table())
    units.set(units.total)
    return BatchResult(rows, fails, timings)


class _Units:
    """The batch's progress in work units, reported as ``progress(done, total)``."""

    def __init__(self, progress: Progress | None, total: float) -> None:
        self.progress, self.total, self.done = progress, total, 0.0

    def set(self, units: float) -> None:
        self.done = units
        if self.progress is not None:
            self.progress(min(self.done, self.total), self.total)

    def add(self, units: float) -> None:
        self.set(self.done + units)


def _shared(recipes: Sequence, field_name: str):
    """The one value of a recipe field every recipe of a batch must share (None without recipes)."""
    values = {getattr(r, field_name) for r in recipes}
    if len(values) > 1:
        shown = sorted(getattr(v, "kind", v) for v in values)
        raise ValueError(f"run_batch: the recipes must share one {field_name}, got {shown}")
    return values.pop() if values else None


def _run_recipe(hand, recipe, all_targets, units: _Units, n_targets: int, fails: list[dict],
                timings: dict[str, float], *, seed, grasps_per_object, splits, base, eval_workers,
                eval_spare_cores) -> list[pa.Table]:
    """One task's synthesis and evaluation over the batch's targets: its evaluated tables (none
    where its synthesis fails, each of its targets then recorded as a failure)."""
    from datagen.tasks import task_targets

    task, synth_cfg = recipe.load_task(), recipe.synth
    if seed is not None:
        synth_cfg = dataclasses.replace(synth_cfg, seed=seed)
    targets = task_targets(task, all_targets)
    if not targets:
        return []
    t0, start = time.perf_counter(), units.done

    def moved(it, *_):  # progress per optimizer iteration (reads nothing of the state)
        units.set(start + n_targets * (it + 1) / max(synth_cfg.iters, 1))

    try:
        _, table = synthesize_rows(hand, targets, task, synth_cfg, grasps_per_object, splits=splits,
                                   grasp_types=recipe.grasp_types, type_synth=recipe.grasp_type_synth,
                                   callback=moved)
    except Exception as exc:  # noqa: BLE001 - the batch's objects fail, the other tasks go on
        for t in targets:
            fails.append(failure(t.object_id, "synth", "error", f"{t.object_id} at {t.scale} m, task "
                                 f"{task.name}: {type(exc).__name__}: {exc}", t.scale, task.name))
        return []
    finally:
        timings["synth_s"] += time.perf_counter() - t0
    units.set(start + n_targets)
    t0 = time.perf_counter()
    tables = evaluate_rows(table, targets, task.name, recipe.eval, base=base, failures=fails,
                           progress=lambda: units.add(n_targets / len(targets)), workers=eval_workers,
                           spare_cores=eval_spare_cores)
    timings["eval_s"] += time.perf_counter() - t0
    return tables
