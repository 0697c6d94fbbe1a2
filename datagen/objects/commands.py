"""CLI subcommand of the objects package: ``manifest`` (``prepare`` is `datagen.pipeline.commands`'s: it
processes with the recipe's settings, as a job does)."""

from __future__ import annotations

import argparse
import sys

__all__ = ["register_manifest"]


def register_manifest(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("manifest", help="object manifests")
    msub = p.add_subparsers(dest="manifest_command", required=True)
    b = msub.add_parser("build", help="enumerate a source into a manifest (JSONL)")
    b.add_argument("--source", default="procedural",
                   help="procedural[:SEED] | tasks | dexgraspnet:PATH | dir:PATH | pybullet")
    b.add_argument("--count", type=int, default=None, help="number of objects (all files if omitted)")
    b.add_argument("--out", required=True, help="output manifest, e.g. manifests/NAME.jsonl")
    b.add_argument("--scales", type=_scale_arg, nargs="+", default=None,
                   help="object scales: metres per normalized unit (the bounding-box diagonal is 2 scale), "
                        "or 'native' to keep the mesh's own size (its coordinates in metres)")
    b.add_argument("--test-fraction", type=float, default=0.1, help="share of objects in the test split")
    b.set_defaults(func=_manifest_build, interrupted="nothing written to {out} (it is written at the end); "
                   "rerun the same command")
    c = msub.add_parser("check", help="validate a manifest")
    c.add_argument("manifest", help="manifest file (JSONL)")
    c.set_defaults(func=_manifest_check, interrupted="nothing was written")


def _scale_arg(text: str):
    if text == "native":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a scale is a number of metres or 'native', got {text!r}") from None


def _manifest_build(args) -> int:
    from .manifest import DEFAULT_SCALES, build_manifest, write_manifest

    entries = build_manifest(args.source, args.count, args.scales or DEFAULT_SCALES,
                             args.test_fraction, progress=sys.stderr.isatty())
    write_manifest(entries, args.out)
    test = sum(e.split == "test" for e in entries)
    print(f"wrote {args.out}: {len(entries)} objects ({test} test)")
    return 0


def _manifest_check(args) -> int:
    from .errors import check_manifest_file

    check_manifest_file(args.manifest)  # a device or a FIFO: refused before the imports below
    from .manifest import load_manifest

    print(f"{args.manifest}: {len(load_manifest(args.manifest))} objects, valid")
    return 0
