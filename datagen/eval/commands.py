"""CLI subcommands of the evaluation: ``datagen eval`` and ``datagen render``.

Both take a grasp table: a Parquet file (``datagen synth`` output, a job's shard, an imported
file) or a job directory (its finished shards). Relative ``object_path`` values are resolved
against the job directory for a job's shards, else against the table's directory
(`datagen.eval.table.table_base`); they must lie inside that directory or the objects cache
unless ``--allow-outside`` is given (`datagen.eval.table.check_object_paths`). ``datagen
render`` picks the offscreen GL backend (`datagen.gl.select_backend`) before mujoco is imported.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

__all__ = ["register_eval", "register_render"]

_TABLE_HELP = "grasp table: a Parquet file (synth output, a job's shard, an imported file) or a job directory"


def _load_config(path: str | None, threads: int | None):
    from .config import EvalConfig

    cfg = EvalConfig.from_yaml(path) if path else EvalConfig()
    if threads is not None:
        cfg = EvalConfig.from_dict({**cfg.to_dict(), "threads": threads})
    return cfg


def register_eval(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="simulate grasps in MuJoCo; add success, reason and metric columns")
    p.add_argument("grasps", help=_TABLE_HELP + " (columns: datagen/eval/table.py)")
    p.add_argument("--out", required=True, help="evaluated table to write (Parquet)")
    p.add_argument("--config", default=None, help="EvalConfig YAML (default: the public protocol's constants)")
    p.add_argument("--workers", type=int, default=1, help="processes evaluating rows in parallel")
    p.add_argument("--threads", type=int, default=None,
                   help="threads per grasp stepping the six directions (default: EvalConfig.threads)")
    _object_options(p)
    p.set_defaults(func=_eval, interrupted="nothing written to {out}; rerun the same command")


def _object_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cache", default=None,
                   help="objects cache the rows' object_path may point into (default $DATAGEN_CACHE, else "
                        "~/.cache/datagen)")
    p.add_argument("--allow-outside", action="store_true",
                   help="read objects wherever the rows' object_path points; by default only inside the job "
                        "(or table) directory and the objects cache")


def _check_objects(args, table, base) -> None:
    from datagen.objects.cache import cache_root

    from .table import check_object_paths

    if not args.allow_outside:
        check_object_paths(table, base, [base, cache_root(args.cache)])


def _eval(args) -> int:
    import pyarrow.parquet as pq

    from datagen._atomic import atomic_path

    from .table import evaluate_table, pin_table_hands, read_grasps, table_base

    cfg = _load_config(args.config, args.threads)
    table = read_grasps(args.grasps)
    base = table_base(args.grasps)
    _check_objects(args, table, base)
    t0 = time.perf_counter()
    out = evaluate_table(table, cfg, base=base, workers=args.workers)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pin_table_hands(out, base, table_base(Path(args.out).resolve().parent))
    with atomic_path(args.out) as tmp:
        pq.write_table(out, tmp)
    ok = sum(out.column("success").to_pylist())
    print(f"wrote {args.out}: {out.num_rows} grasps, {ok} successful, "
          f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0


def register_render(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="PNG pictures of grasps (initial pose, grasp, after the squeeze)")
    p.add_argument("grasps", help=_TABLE_HELP)
    p.add_argument("--out", required=True, help="output directory (grasp_<row>_<object_id>.png)")
    p.add_argument("--rows", type=int, nargs="+", default=None, help="row indices (default: the first 4)")
    p.add_argument("--config", default=None, help="EvalConfig YAML (default: the public protocol's constants)")
    p.add_argument("--width", type=int, default=320, help="width of one view, pixels")
    p.add_argument("--height", type=int, default=240, help="height of one view, pixels")
    _object_options(p)
    p.set_defaults(func=_render, interrupted="the pictures already in {out} are complete; rerun the same command "
                   "for all of them")


def _render(args) -> int:
    from datagen.gl import select_backend

    select_backend()  # before mujoco is imported (raises GLUnavailable naming what is missing)

    from datagen.hands import load_hand

    from .render import render_grasp
    from .scene import build_scene
    from .table import read_grasps, row_pieces, row_poses, row_table, table_base

    cfg = _load_config(args.config, None)
    table = read_grasps(args.grasps)
    base = table_base(args.grasps)
    _check_objects(args, table, base)
    indices = args.rows if args.rows is not None else list(range(min(4, table.num_rows)))
    hands = {}
    for i in indices:
        if not 0 <= i < table.num_rows:
            raise ValueError(f"row {i} is out of range (the table has {table.num_rows} rows)")
        row = table.slice(i, 1).to_pylist()[0]
        name = str(row["hand"])
        hands.setdefault(name, load_hand(name, base=base))
        table_plane = row_table(row)  # a tabletop row: its table, the lift (no task test)
        test = None if table_plane is not None else cfg.task_test(str(row["task"]))
        scene = build_scene(hands[name], row_pieces(row, base), cfg, test, table=table_plane)
        path = render_grasp(scene, row_poses(row), cfg, Path(args.out) / f"grasp_{i:06d}_{row['object_id']}.png",
                            width=args.width, height=args.height)
        print(path)
    return 0
