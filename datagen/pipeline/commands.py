"""CLI: ``datagen synth --hand shadow --object PATH --task force_closure --num 100 --out F.parquet``.

The synthesis half of the pipeline (`datagen.pipeline`: target -> synthesis -> rows) on one
object, with the recipe a job resolves (`datagen.pipeline.resolve`); ``datagen eval`` evaluates
the table it writes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_recipe_arguments", "read_config", "recipe_flags", "register_hand", "register_prepare", "register_synth"]


def add_recipe_arguments(p: argparse.ArgumentParser) -> None:
    """The flags that set a recipe (`datagen.pipeline.resolve`), shared by ``synth`` and ``run``:
    each is unset unless given, so a flag equal to a default still wins over a task's block."""
    p.add_argument("--preset", default=None, help="settings preset: dataset (a job's, the default) or paper "
                   "(one start per pose, 500 iterations)")
    p.add_argument("--iters", type=int, default=None, help="optimizer iterations (default: the preset's)")
    p.add_argument("--seeds", type=int, default=None, dest="seeds_per_grasp",
                   help="multi-start: initial poses per output grasp, the best after seed_select_iter iterations "
                        "goes on (default: the preset's, or the task's)")
    p.add_argument("--grasp-type", default=None, dest="grasp_type",
                   help="every force-closure grasp of this grasp type (`datagen/tasks/grasp_types`: precision, "
                        "power; or a YAML), instead of the preset's choice by object size")
    p.add_argument("--scene", default=None, choices=("floating", "tabletop"),
                   help="floating (in space, the six-direction test; the default) or tabletop (the object resting "
                        "on a table in its stable poses, the lift test; docs/scenes.md)")
    p.add_argument("--stable-poses", type=int, default=None, dest="stable_poses",
                   help="tabletop: stable poses per object, the most probable first (default 1)")


def recipe_flags(args) -> dict:
    """The recipe layer of the flags `add_recipe_arguments` added (only those given)."""
    synth = {k: v for k, v in (("iters", args.iters), ("seeds_per_grasp", args.seeds_per_grasp)) if v is not None}
    out = {"synth": synth} if synth else {}
    if args.preset is not None:
        out["preset"] = args.preset
    if args.grasp_type is not None:
        out["grasp_types"] = args.grasp_type
    scene = {k: v for k, v in (("kind", args.scene), ("stable_poses", args.stable_poses)) if v is not None}
    if scene:
        out["scene"] = scene
    return out


def read_config(path: str | None) -> dict:
    """The config file's mapping ({} for None): bounded YAML (`datagen.objects.config.read_yaml`);
    raises `ConfigError` naming the file for anything but a mapping, and for SynthConfig fields at
    the top level (they belong under ``synth:``)."""
    from datagen.config import read_yaml
    from datagen.errors import ConfigError
    from datagen.eval.config import EvalConfig
    from datagen.objects.config import ProcessConfig
    from datagen.synth import SynthConfig

    if path is None:
        return {}
    try:
        data = read_yaml(path, "config")
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a config must be a mapping (preset, synth, eval, process, ...)")
    for part, cls in (("synth", SynthConfig), ("eval", EvalConfig), ("process", ProcessConfig)):
        loose = sorted(set(data) & set(cls.__dataclass_fields__))
        if loose:
            raise ConfigError(f"{path}: {cls.__name__} fields {loose} at the top level", f"put them under `{part}:`")
    return data


def register_synth(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="synthesize hand poses on one object")
    p.add_argument("--hand", default="shadow", help="built-in hand name or a hand spec YAML")
    p.add_argument("--object", required=True, help="raw mesh file or processed-object directory")
    p.add_argument("--scale", type=float, nargs="+", default=[0.08],
                   help="object size(s), metres per normalized object unit (not a count)")
    p.add_argument("--task", default="force_closure", help="built-in task name or task YAML")
    p.add_argument("--num", type=int, default=100, help="grasps per object scale")
    p.add_argument("--config", default=None, help="YAML config: preset, synth, eval, process, grid_resolution "
                   "mappings (a job config file works: its other keys are ignored); the flags go on top")
    add_recipe_arguments(p)
    p.add_argument("--seed", type=int, default=None, help="synthesis seed (default: 0)")
    p.add_argument("--cache", default=None, help="objects cache root (default $DATAGEN_CACHE)")
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when available)")
    p.add_argument("--out", required=True, help="output Parquet file")
    p.set_defaults(func=_synth, interrupted="nothing written to {out}; rerun the same command (a processed object "
                   "stays in the cache)")


def _synth(args) -> int:
    if args.num < 1:
        raise ValueError(f"--num must be >= 1 (grasps per object scale), got {args.num}")
    import pyarrow.parquet as pq
    import torch

    from datagen._atomic import atomic_path
    from datagen.hands import load_hand, pin_hand

    from .api import load_object
    from .batch import BatchObject, build_targets, synthesize_rows
    from .recipe import merge_layers, resolve

    flags = merge_layers(recipe_flags(args), {"synth": {"seed": args.seed}} if args.seed is not None else {})
    recipe = resolve(args.hand, args.task, config=read_config(args.config), flags=flags,
                     where=args.config or "config")
    cfg = recipe.synth
    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    hand = load_hand(args.hand, device=device)
    # the table's folder keeps the hand its rows name (hands/<name>.yaml, written with the table):
    # eval, render, view and export load it from there; refused now if another hand holds the name
    folder = Path(args.out).resolve().parent
    pin_hand(hand.spec, folder, write=False)
    processed = load_object(args.object, recipe.process, args.cache)
    targets = build_targets([BatchObject(processed, tuple(args.scale))], grid_resolution=recipe.grid_resolution,
                            cache=args.cache, device=device, scene=recipe.scene)

    def progress(it, x, e, ok):
        if sys.stderr.isatty() and (it % 50 == 0 or it == cfg.iters - 1):
            print(f"\r  iter {it + 1}/{cfg.iters}  energy {e.mean():.4f}  accepted {ok.float().mean():.0%}",
                  end="", file=sys.stderr, flush=True)

    results, table = synthesize_rows(hand, targets, recipe.load_task(), cfg, args.num,
                                     grasp_types=recipe.grasp_types, type_synth=recipe.grasp_type_synth,
                                     callback=progress)
    usable = int(sum(r.usable(cfg.contact_threshold_m).sum() for r in results))
    if usable == 0:
        e = {k: float(torch.cat([r.energies[k] for r in results]).mean()) for k in results[0].energies}
        gap = min(float(r.tip_distance.abs().amax(-1).min()) for r in results) * 1000
        pen = min(float(r.max_penetration.min()) for r in results) * 1000
        print(f"datagen synth: error: no usable grasp among {table.num_rows} on {args.object} "
              f"(best contact gap {gap:.1f} mm > {cfg.contact_threshold_m * 1000:.1f} mm or penetration "
              f"{pen:.1f} mm > 5 mm); mean energies {e}. Nothing written to {args.out}.", file=sys.stderr)
        return 3
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pin_hand(hand.spec, folder)
    with atomic_path(args.out) as tmp:
        pq.write_table(table, tmp)
    print(f"\nwrote {args.out}: {table.num_rows} grasps, {usable} usable "
          f"({sum(r.timings['optimize_s'] for r in results):.1f} s optimizing on {device})")
    return 0


def register_prepare(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("prepare", help="process manifest objects into the cache")
    p.add_argument("--manifest", required=True, help="manifest file (JSONL) of the objects to process")
    p.add_argument("--preset", default=None, help="settings preset whose processing is used (default: dataset, "
                   "so a job reuses the objects)")
    p.add_argument("--config", default=None, help="YAML config; its process mapping (ProcessConfig fields) is used")
    p.add_argument("--cache", default=None, help="cache root (default $DATAGEN_CACHE or ~/.cache/datagen)")
    p.add_argument("--workers", type=int, default=1, help="objects processed in parallel")
    p.add_argument("--limit", type=int, default=None, help="process only the first N objects")
    p.add_argument("--timeout", type=float, default=None,
                   help="seconds one object may take; it is then killed and recorded as a timeout failure "
                        "(default: 600)")
    p.add_argument("--results", default=None, help="write one status line per object (JSONL)")
    p.set_defaults(func=_prepare, interrupted="the objects finished so far are in the cache and are not processed "
                   "again (no --results file was written); rerun the same command to process the rest")


def _prepare(args) -> int:
    from datagen.objects.errors import check_manifest_file

    check_manifest_file(args.manifest)  # refused before the imports below
    config = read_config(args.config)
    from datagen.objects.prepare import DEFAULT_TIMEOUT_S, prepare, summarize, write_results

    from .recipe import resolve

    cfg = resolve(preset=args.preset, config=config, where=args.config or "config").process
    results = prepare(args.manifest, cfg, args.cache, args.workers, progress=True, limit=args.limit,
                      timeout_s=DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout)
    if args.results:
        write_results(results, args.results)
    print(summarize(results, args.results))
    return 0


def register_hand(sub: argparse._SubParsersAction) -> None:
    """``datagen hand init|check|calibrate``: init and check from `datagen.hands.commands`,
    calibrate (synthesis + the MuJoCo test on procedural objects) from `datagen.pipeline.calibrate`."""
    from datagen.hands.commands import add_init_and_check

    p = sub.add_parser("hand", help="bring your own hand: propose a spec for an MJCF/URDF (init), check an "
                       "edited one (check), tune it on procedural objects (calibrate)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    add_init_and_check(actions)
    cal = actions.add_parser("calibrate", help="choose the hand's sphere margin by a short, paired synthesis + "
                             "MuJoCo run on procedural objects (minutes); writes the choice into the spec")
    cal.add_argument("spec", help="hand spec YAML (rewritten with the choice unless --out is given)")
    cal.add_argument("--out", default=None, help="write the calibrated spec here instead")
    cal.add_argument("--objects", type=int, default=6, help="procedural objects of the run")
    cal.add_argument("--grasps", type=int, default=3, help="grasps per object, scale and candidate")
    cal.add_argument("--seed", type=int, default=0, help="seed of the run")
    cal.add_argument("--cache", default=None, help="objects cache root (default $DATAGEN_CACHE)")
    cal.set_defaults(func=_calibrate, interrupted="the spec is unchanged; rerun the same command")


def _calibrate(args) -> int:
    from .calibrate import calibrate_spec, format_calibration

    result = calibrate_spec(args.spec, out=args.out, objects=args.objects, grasps=args.grasps, seed=args.seed,
                            cache=args.cache, log=lambda line: print(line, file=sys.stderr, flush=True))
    print(format_calibration(result))
    return 0
