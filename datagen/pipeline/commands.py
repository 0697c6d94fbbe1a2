"""CLI: ``datagen synth --hand shadow --object PATH --task force_closure --num 100 --out F.parquet``.

The synthesis half of the pipeline (`datagen.pipeline`: target -> synthesis -> rows) on one
object; ``datagen eval`` evaluates the table it writes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["load_object", "register_hand", "register_synth"]


def load_object(path: str | Path, cache: str | None = None, process_config: str | None = None):
    """The processed object (`datagen.objects.ProcessedObject`, status ok) of a raw mesh file
    (processed through the objects cache, in a child process as `datagen prepare` does it: a
    Ctrl-C or a CoACD crash ends only that process) or of a processed-object directory (one holding
    ``meta.json``). Raises FileNotFoundError or ValueError naming the object and the reason."""
    from datagen.objects import layout
    from datagen.objects.config import ProcessConfig
    from datagen.objects.isolate import process_isolated
    from datagen.objects.manifest import ManifestEntry
    from datagen.objects.prepare import DEFAULT_TIMEOUT_S
    from datagen.objects.process import load_processed
    from datagen.objects.sources import resolve

    p = Path(path)
    if p.is_dir() and (p / layout.META).is_file():
        processed = load_processed(p)
    elif p.is_file():
        ref = resolve(f"dir:{p.parent.resolve()}", p.name, p.stem)
        cfg = ProcessConfig.from_yaml(process_config) if process_config else ProcessConfig()
        processed = process_isolated(ManifestEntry.of_ref(ref), cfg, cache, DEFAULT_TIMEOUT_S,
                                     remedy="process it first with `datagen prepare --timeout SECONDS`")
    else:
        raise FileNotFoundError(f"object {p} is neither a mesh file nor a processed-object directory")
    if not processed.ok:
        raise ValueError(f"object {p}: processing failed ({processed.reason}): {processed.message}")
    return processed


def register_synth(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="synthesize hand poses on one object")
    p.add_argument("--hand", default="shadow", help="built-in hand name or a hand spec YAML")
    p.add_argument("--object", required=True, help="raw mesh file or processed-object directory")
    p.add_argument("--scale", type=float, nargs="+", default=[0.08],
                   help="object size(s), metres per normalized object unit (not a count)")
    p.add_argument("--task", default="force_closure", help="built-in task name or task YAML")
    p.add_argument("--num", type=int, default=100, help="grasps per object scale")
    p.add_argument("--iters", type=int, default=None, help="optimizer iterations (default: config)")
    p.add_argument("--config", default=None, help="YAML of SynthConfig fields")
    p.add_argument("--seed", type=int, default=None, help="synthesis seed (default: the config's, 0)")
    p.add_argument("--seeds", type=int, default=None, dest="seeds_per_grasp",
                   help="multi-start: initial poses per output grasp, the best of them after seed_select_iter "
                        "iterations goes on (default: for force closure without --config, the job default "
                        "datagen.synth.config.FORCE_CLOSURE_SEEDS; else the config's)")
    p.add_argument("--cache", default=None, help="objects cache root (default $DATAGEN_CACHE)")
    p.add_argument("--device", default=None, help="cpu or cuda (default: cuda when available)")
    p.add_argument("--out", required=True, help="output Parquet file")
    p.set_defaults(func=_synth, interrupted="nothing written to {out}; rerun the same command (a processed object "
                   "stays in the cache)")


def _synth(args) -> int:
    if args.num < 1:
        raise ValueError(f"--num must be >= 1 (grasps per object scale), got {args.num}")
    import dataclasses

    import pyarrow.parquet as pq
    import torch

    from datagen._atomic import atomic_path
    from datagen.config import read_yaml
    from datagen.hands import load_hand, pin_hand
    from datagen.pipeline import BatchObject, build_targets, synthesize_rows
    from datagen.synth import SynthConfig
    from datagen.tasks import load_task

    cfg = SynthConfig.from_dict(read_yaml(args.config, "synthesis config") if args.config else {},
                                where=args.config or "defaults")
    from datagen.synth.config import FORCE_CLOSURE_SEEDS

    if args.seeds_per_grasp is None and args.config is None and args.task == "force_closure":
        args.seeds_per_grasp = FORCE_CLOSURE_SEEDS
    overrides = {k: v for k, v in (("iters", args.iters), ("seed", args.seed),
                                   ("seeds_per_grasp", args.seeds_per_grasp)) if v is not None}
    cfg = dataclasses.replace(cfg, **overrides)
    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    hand = load_hand(args.hand, device=device)
    # the table's folder keeps the hand its rows name (hands/<name>.yaml, written with the table):
    # eval, render, view and export load it from there; refused now if another hand holds the name
    folder = Path(args.out).resolve().parent
    pin_hand(hand.spec, folder, write=False)
    task = load_task(args.task)
    processed = load_object(args.object, args.cache)
    # one batch object per scale: each target built at its own scale (grid from the grid cache)
    targets = build_targets([BatchObject(processed, (s,)) for s in args.scale], cache=args.cache, device=device)

    def progress(it, x, e, ok):
        if sys.stderr.isatty() and (it % 50 == 0 or it == cfg.iters - 1):
            print(f"\r  iter {it + 1}/{cfg.iters}  energy {e.mean():.4f}  accepted {ok.float().mean():.0%}",
                  end="", file=sys.stderr, flush=True)

    result, table = synthesize_rows(hand, targets, task, cfg, args.num, callback=progress)
    usable = int(result.usable(cfg.contact_threshold_m).sum())
    if usable == 0:
        e = {k: float(v.mean()) for k, v in result.energies.items()}
        gap = float(result.tip_distance.abs().amax(-1).min()) * 1000
        pen = float(result.max_penetration.min()) * 1000
        print(f"datagen synth: error: no usable grasp among {table.num_rows} on {args.object} "
              f"(best contact gap {gap:.1f} mm > {cfg.contact_threshold_m * 1000:.1f} mm or penetration "
              f"{pen:.1f} mm > 5 mm); mean energies {e}. Nothing written to {args.out}.", file=sys.stderr)
        return 3
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    pin_hand(hand.spec, folder)
    with atomic_path(args.out) as tmp:
        pq.write_table(table, tmp)
    print(f"\nwrote {args.out}: {table.num_rows} grasps, {usable} usable "
          f"({result.timings['optimize_s']:.1f} s optimizing on {device})")
    return 0


def register_hand(sub: argparse._SubParsersAction) -> None:
    """``datagen hand init|check|calibrate``: init and check from `datagen.hands.commands`,
    calibrate (synthesis + the MuJoCo test on procedural objects) from `datagen.pipeline.calibrate`."""
    from datagen.hands.commands import add_init_and_check

    p = sub.add_parser("hand", help="bring your own hand: propose a spec for an MJCF/URDF (init), check an "
                       "edited one (check), tune it on procedural objects (calibrate)")
    actions = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    add_init_and_check(actions)
    cal = actions.add_parser("calibrate", help="choose the hand's sphere margin by a short synthesis + MuJoCo run "
                             "on procedural objects; writes the choice into the spec")
    cal.add_argument("spec", help="hand spec YAML (rewritten with the choice unless --out is given)")
    cal.add_argument("--out", default=None, help="write the calibrated spec here instead")
    cal.add_argument("--objects", type=int, default=4, help="procedural objects of the run")
    cal.add_argument("--grasps", type=int, default=4, help="grasps per object, scale and candidate")
    cal.add_argument("--seed", type=int, default=0, help="seed of the run")
    cal.add_argument("--cache", default=None, help="objects cache root (default $DATAGEN_CACHE)")
    cal.set_defaults(func=_calibrate, interrupted="the spec is unchanged; rerun the same command")


def _calibrate(args) -> int:
    from .calibrate import calibrate_spec, format_calibration

    result = calibrate_spec(args.spec, out=args.out, objects=args.objects, grasps=args.grasps, seed=args.seed,
                            cache=args.cache, log=lambda line: print(line, file=sys.stderr, flush=True))
    print(format_calibration(result))
    return 0
