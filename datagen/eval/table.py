"""Grasp tables in and out: the columns ``datagen eval`` reads and the ones it adds.

Input (Parquet, one row per grasp; other columns are kept as they are):

    object_id       string
    object_scale_m  float   metres per normalized unit (``object_scale``, its name before schema 2, is
                    accepted too)
    hand            string  the hand's name: one pinned in the table's folder (``hands/<name>.yaml``,
                    `datagen.hands.pin`), else a built-in hand name (`datagen.hands.load_hand`)
    task            string  ``force_closure`` (six directions) or a task of `EvalConfig.tasks`
    pregrasp_qpos, grasp_qpos, squeeze_qpos
                    list<float32> (7 + J): [x y z qw qx qy qz] + joints in the hand MJCF's joint
                    order, object frame (metres, radians)
    object_path     string  the processed object's cache entry directory (``ProcessedObject.entry``:
                    meta.json, coacd/ pieces): absolute, or relative to the job directory for a
                    job's shards and to the table's own directory otherwise (`table_base`)
    w_t             list<float32> (6), optional: the task wrench; used by task tests (see
                    `Evaluator.evaluate`), ignored by the six-direction test
    scene, support_plane
                    optional: a ``tabletop`` row's support plane (4) gets the lift test
                    (`datagen.eval.lift`) instead of the six directions

Output: the input columns plus `EVAL_COLUMNS` (declared in schemas/evaluated.json; units in the
names). Row order is kept.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import pickle
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from datagen._interrupt import on_sigint, sigint_blocked
from schemas import arrow_schema, declaration

from .config import EvalConfig, EvalError
from .evaluate import Evaluator, GraspResult
from .scene import ObjectPieces, pieces_from_processed

__all__ = ["INPUT_COLUMNS", "EVAL_COLUMNS", "EVAL_SCHEMA_VERSION", "append_results", "check_object_paths",
           "evaluate_table", "pin_table_hands", "read_grasps", "row_poses", "row_pieces", "row_table", "table_base"]

EVAL_SCHEMA_VERSION = int(declaration("evaluated")["version"])
INPUT_COLUMNS = ("object_id", "object_scale_m", "hand", "task", "pregrasp_qpos", "grasp_qpos", "squeeze_qpos",
                 "object_path")
# name -> (Arrow type, description): the `evaluated` schema's own columns (schemas/evaluated.json)
EVAL_COLUMNS: dict[str, tuple[pa.DataType, str]] = {
    c["name"]: (arrow_schema("evaluated", nq=1).field(c["name"]).type,
                c["doc"] + (f" ({c['unit']})" if c.get("unit") else ""))
    for c in declaration("evaluated")["columns"]}
# columns renamed in schema version 2, still accepted in input tables
_RENAMED = {"object_scale": "object_scale_m"}


def table_base(path: str | Path) -> Path:
    """The directory relative ``object_path`` values of the table at ``path`` are resolved against:
    the job directory when ``path`` is a job directory or lies inside one (a shard
    ``JOB/shards/part-NNNNN.parquet``: rows name ``objects/<entry>`` relative to ``JOB``), else the
    table's own directory."""
    from datagen.io import layout

    path = Path(path).resolve()
    for d in ([path] if path.is_dir() else []) + list(path.parents):
        if (d / layout.JOB_JSON).is_file():
            return d
    return path if path.is_dir() else path.parent


def read_grasps(path: str | Path) -> pa.Table:
    """Read a grasp table (a Parquet file, or a job directory: its finished shards) and check its
    columns (raises `EvalError` naming the missing ones). Resolve its rows' ``object_path`` against
    `table_base` (path)."""
    path = Path(path)
    if path.is_dir():
        from datagen.io import read_job

        try:
            table = read_job(path)
        except FileNotFoundError as exc:
            raise EvalError(str(path), f"not a grasp table: {exc}",
                            "pass a Parquet grasp table or a job directory with finished shards") from None
    elif path.is_file():  # a regular file (not a FIFO or a device)
        try:
            table = pq.read_table(path)
        except (OSError, pa.ArrowException) as exc:
            raise EvalError(str(path), f"not a readable Parquet grasp table ({' '.join(str(exc).split())})") from None
        for old, new in _RENAMED.items():
            if old in table.column_names and new not in table.column_names:
                table = table.rename_columns([new if c == old else c for c in table.column_names])
    else:
        raise EvalError(str(path), "grasp table not found")
    missing = [c for c in INPUT_COLUMNS if c not in table.column_names]
    if missing:
        raise EvalError(str(path), f"missing columns {missing}", f"a grasp table needs {list(INPUT_COLUMNS)}")
    return table


def check_object_paths(table: pa.Table, base: Path, roots: list[Path]) -> None:
    """Refuse (`EvalError` naming the row's object, its path and the allowed places) a table row
    whose ``object_path``, resolved against ``base`` (symbolic links followed), lies outside every
    folder of ``roots`` (for ``datagen eval``: the job or table directory and the objects cache).
    A grasp table is data: it must not make the evaluator read files anywhere (``/etc``,
    ``../..``, another job's objects)."""
    roots = [Path(r).resolve() for r in roots]
    ids = table["object_id"].to_pylist()
    for i, rel in enumerate(table["object_path"].to_pylist()):
        entry = Path(str(rel))
        target = (entry if entry.is_absolute() else base / entry).resolve()
        if not any(target.is_relative_to(r) for r in roots):
            raise EvalError(f"row {i} (object {ids[i]!r})", f"object_path {rel!r} resolves to {target}, outside "
                            + " and ".join(str(r) for r in roots),
                            "pass --allow-outside to read objects from there, or --cache with the objects cache "
                            "the table was made with")


def row_poses(row: dict) -> np.ndarray:
    """(3, 7 + J) float64 pregrasp, grasp, squeeze of a table row."""
    rows = [np.asarray(row[k], dtype=np.float64) for k in ("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")]
    if len({r.shape for r in rows}) != 1 or rows[0].ndim != 1:
        raise EvalError(f"grasp of object {row.get('object_id')!r}", "pregrasp/grasp/squeeze rows differ in length")
    return np.stack(rows)


def row_table(row: dict):
    """(4,) the support plane of a tabletop row, None for a floating one (or a table without the
    scene columns, written before schema 4)."""
    return row["support_plane"] if row.get("scene") == "tabletop" else None


def row_pieces(row: dict, base: Path) -> ObjectPieces:
    """The object of a table row (``object_path`` resolved against ``base``)."""
    from datagen.objects import load_processed

    entry = Path(row["object_path"])
    entry = entry if entry.is_absolute() else base / entry
    try:
        processed = load_processed(entry)
    except (OSError, ValueError, KeyError) as exc:
        raise EvalError(f"object {row['object_id']!r}", f"cannot read the processed object at {entry}: {exc}",
                        "object_path must be a processed object's cache entry (datagen prepare)") from None
    return pieces_from_processed(processed, float(row["object_scale_m"]))


def _evaluate_rows(rows: list[dict], base: str, cfg_dict: dict, spare_cores=None,
                   evaluators: dict | None = None) -> list[GraspResult]:
    """Evaluate rows in this process (one `Evaluator` per hand; ``spare_cores`` as there).
    ``evaluators``: the caller's {(hand, base, config): Evaluator}, kept across calls (the hand
    loaded and the scenes built once; the caller closes them); None: made and closed here."""
    import torch

    from datagen.hands import load_hand

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # one core per worker; the epsilon search is small
    cfg = EvalConfig.from_dict(cfg_dict)
    own, cfg_key = evaluators is None, cfg.hash()
    evaluators = {} if own else evaluators
    out = []
    try:
        for row in rows:
            key = (str(row["hand"]), str(base), cfg_key)
            if key not in evaluators:
                evaluators[key] = Evaluator(load_hand(key[0], base=base), cfg, spare_cores=spare_cores)
            out.append(evaluators[key].evaluate(row_pieces(row, Path(base)), row_poses(row), str(row["task"]),
                                                w_t=row.get("w_t"), table=row_table(row)))
    finally:
        if own:
            for ev in evaluators.values():
                ev.close()
        torch.set_num_threads(threads)  # in the caller's process: its synthesis keeps its threads
    return out


def _evaluate_rows_pooled(rows: list[dict], base: str, cfg_dict: dict):
    """`_evaluate_rows` in a pool worker: an error comes back as a value the parent re-raises. An
    exception that cannot be unpickled would otherwise stop the pool's result thread and leave the
    caller waiting forever."""
    try:
        return _evaluate_rows(rows, base, cfg_dict)
    except Exception as exc:  # noqa: BLE001 - re-raised by the parent
        try:
            return pickle.loads(pickle.dumps(exc))
        except Exception:  # noqa: BLE001
            return RuntimeError(f"{type(exc).__name__}: {exc}")


def pool_context() -> mp.context.BaseContext:
    """The evaluation pool's start method: the platform's (fork on Linux), but spawn once this
    process has used CUDA. Autograd on a GPU starts device threads that a fork cannot carry, and
    PyTorch then refuses any backward pass in the child ("Unable to handle autograd's threading in
    combination with fork-based multiprocessing"), which failed every grasp of a GPU shard with
    several CPUs (seen on an H200, benchmarks/results/cuda_check.md). A spawned worker starts a
    fresh interpreter (about a second more per pool)."""
    import torch

    return mp.get_context("spawn" if torch.cuda.is_initialized() else None)


def evaluate_table(table: pa.Table, cfg: EvalConfig, *, base: str | Path = ".", workers: int = 1,
                   spare_cores=None, evaluators: dict | None = None) -> pa.Table:
    """``table`` with `EVAL_COLUMNS` appended (replaced if present). ``workers`` > 1 splits the
    rows into contiguous chunks evaluated by a process pool (results are identical); with one,
    ``spare_cores`` (see `Evaluator`) lets a grasp use an idle core, and ``evaluators`` (a dict
    the caller keeps and closes, see `_evaluate_rows`) carries the loaded hand and built scenes
    from one call to the next (the same verdicts)."""
    names = list(INPUT_COLUMNS) + [c for c in ("w_t", "scene", "support_plane") if c in table.column_names]
    rows = table.select(names).to_pylist()
    cfg_d = cfg.to_dict()
    if workers <= 1 or len(rows) < 2:
        results = _evaluate_rows(rows, str(base), cfg_d, spare_cores, evaluators)
    else:
        n = min(workers, len(rows))
        bounds = np.linspace(0, len(rows), n + 1).astype(int)
        # workers ignore Ctrl-C; interrupted, this process ends them (the pool's exit: terminate)
        with sigint_blocked():
            pool = pool_context().Pool(n, initializer=on_sigint, initargs=("ignore",))
        with pool:
            parts = pool.starmap(_evaluate_rows_pooled, [(rows[a:b], str(base), cfg_d)
                                                         for a, b in zip(bounds[:-1], bounds[1:])])
        for part in parts:
            if isinstance(part, BaseException):
                raise part
        results = [r for part in parts for r in part]
    return append_results(table, results)


def pin_table_hands(table: pa.Table, base: str | Path, out_base: str | Path) -> None:
    """Pin the hands ``table``'s rows name (as loaded from ``base``) in ``out_base`` as well: a
    table written to another folder than its input's takes its hands along (`datagen.hands.pin`)."""
    from datagen.hands import hand_spec_path, load_spec, pin_hand

    if Path(base).resolve() == Path(out_base).resolve():
        return
    for name in sorted(set(table.column("hand").to_pylist())):
        pin_hand(load_spec(hand_spec_path(str(name), base)), out_base)


def _f(x: float) -> float | None:
    return None if x is None else float(x)


def append_results(table: pa.Table, results: list[GraspResult]) -> pa.Table:
    """``table`` with the `EVAL_COLUMNS` of ``results`` (one per row, same order)."""
    if len(results) != table.num_rows:
        raise EvalError("eval results", f"{len(results)} results for {table.num_rows} rows")
    values = {
        "success": [r.success for r in results],
        "reason": [r.reason for r in results],
        "eval_test": [r.test for r in results],
        "dir_success": [list(r.direction_success) for r in results],
        "dir_translation_m": [[_f(x) for x in r.direction_translation_m] for r in results],
        "dir_rotation_deg": [[_f(x) for x in r.direction_rotation_deg] for r in results],
        "pregrasp_penetration_m": [r.pregrasp_penetration_m for r in results],
        "penetration_m": [r.penetration_m for r in results],
        "self_penetration_m": [r.self_penetration_m for r in results],
        "min_distance_m": [r.min_distance_m for r in results],
        "finger_distance_m": [[_f(x) for x in r.finger_distance_m] for r in results],
        "touching_links": [r.touching_links for r in results],
        "num_contacts": [r.num_contacts for r in results],
        "epsilon": [r.epsilon if not math.isnan(r.epsilon) else float("nan") for r in results],
        "table_penetration_m": [r.table_penetration_m for r in results],
    }
    for name, (dtype, _) in EVAL_COLUMNS.items():
        col = pa.array(values[name], type=dtype)
        if name in table.column_names:
            table = table.set_column(table.column_names.index(name), name, col)
        else:
            table = table.append_column(name, col)
    meta = dict(table.schema.metadata or {})
    meta[b"datagen.eval_schema_version"] = str(EVAL_SCHEMA_VERSION).encode()
    if meta.get(b"datagen.schema") == b"grasps":  # no longer a grasps table: relabel it (or unlabel it)
        from schemas import columns, declaration

        meta.pop(b"datagen.schema"), meta.pop(b"datagen.schema_version", None)
        if table.column_names == [c["name"] for c in columns("evaluated")]:
            meta[b"datagen.schema"] = b"evaluated"
            meta[b"datagen.schema_version"] = str(declaration("evaluated")["version"]).encode()
    return table.replace_schema_metadata(meta)
