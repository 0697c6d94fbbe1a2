"""CLI: ``datagen export SOURCE --format dexgraspbench --out DIR`` and
``datagen import --format dexgraspbench|bodex FILES --hand NAME --out TABLE.parquet``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["register_export", "register_import"]

FORMATS_OUT = ("dexgraspbench",)
FORMATS_IN = ("dexgraspbench", "bodex")


def register_export(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a job's grasps in a peer's format (DexGraspBench .npy files)")
    p.add_argument("source", help="job directory (its finished shards) or a grasp table (Parquet)")
    p.add_argument("--format", choices=FORMATS_OUT, default="dexgraspbench", help="output format")
    p.add_argument("--out", required=True, help="output directory (graspdata/ and objects/ are written there)")
    p.add_argument("--only-success", action="store_true", help="export only grasps with success = true")
    p.set_defaults(func=_export, interrupted="the grasp files and objects already under {out} are complete; rerun "
                   "the same command to write them all")


def _export(args) -> int:
    import pyarrow.compute as pc
    import torch

    from datagen.eval.table import read_grasps, table_base
    from datagen.hands import load_hand

    from .dexgraspbench import export_grasps

    table = read_grasps(args.source)
    if args.only_success:
        if "success" not in table.column_names:
            raise ValueError(f"{args.source}: no success column (evaluate it first: datagen eval)")
        table = table.filter(pc.equal(table["success"], True))
    hands = sorted(set(table["hand"].to_pylist()))
    base = table_base(args.source)
    written = []
    for name in hands:
        part = table.filter(pc.equal(table["hand"], name))
        written += export_grasps(part, base, Path(args.out), load_hand(name, dtype=torch.float64, base=base))
    print(f"wrote {len(written)} DexGraspBench grasp files under {Path(args.out) / 'graspdata'} "
          f"(objects under {Path(args.out) / 'objects'})", file=sys.stderr)
    return 0


def register_import(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="read a peer's grasp files into a grasp table that datagen eval/render take")
    p.add_argument("files", nargs="+", help="grasp files or directories searched for them (*.npy)")
    p.add_argument("--format", choices=FORMATS_IN, required=True, help="input format")
    p.add_argument("--hand", required=True, help="our name of the peer's hand (shadow_e3m5, allegro, leap)")
    p.add_argument("--out", required=True, help="grasp table to write (Parquet); objects go to its objects/ folder")
    p.add_argument("--root", default=None,
                   help="dexgraspbench: directory relative obj_path values are resolved against (default: the "
                        "current one); bodex: BODex's src/curobo/content directory, for scene paths written "
                        "on another machine")
    p.add_argument("--task", default="force_closure", help="task recorded on the rows (the test datagen eval runs)")
    p.set_defaults(func=_import, interrupted="nothing written to {out} (the objects already imported into its "
                   "objects/ folder are complete); rerun the same command")


def _files(items: list[str]) -> list[Path]:
    out = []
    for it in items:
        p = Path(it)
        if p.is_dir():
            out += sorted(p.rglob("*.npy"))
        elif p.is_file():
            out.append(p)
        else:
            raise FileNotFoundError(f"{p}: no such file or directory")
    if not out:
        raise FileNotFoundError(f"no .npy grasp files in {items}")
    return out


def _import(args) -> int:
    import pyarrow.parquet as pq
    import torch

    from datagen._atomic import atomic_path
    from datagen.hands import load_hand, pin_hand

    from .rows import imported_table

    hand = load_hand(args.hand, dtype=torch.float64)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    pin_hand(hand.spec, out.resolve().parent, write=False)  # refused now if another hand holds the name
    files = _files(args.files)
    root = Path(args.root) if args.root else None
    if args.format == "dexgraspbench":
        from .dexgraspbench import read_grasp_files

        cols = read_grasp_files(files, hand, out.parent / "objects", root)
    else:
        from .bodex import read_bodex_files

        cols = read_bodex_files(files, hand, out.parent / "objects", root)
    table = imported_table(cols, hand, args.format, args.task)
    pin_hand(hand.spec, out.resolve().parent)  # the rows name it: eval and render load it from there
    with atomic_path(out) as tmp:
        pq.write_table(table, tmp)
    print(f"wrote {out}: {table.num_rows} grasps of {len(set(cols['object_id']))} objects; next: "
          f"datagen eval {out} --out EVALUATED.parquet", file=sys.stderr)
    return 0
