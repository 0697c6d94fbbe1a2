"""CLI subcommands of the objects package: ``manifest build`` and ``prepare``."""

from __future__ import annotations

import argparse
import sys

__all__ = ["register_manifest", "register_prepare"]


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


def register_prepare(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("prepare", help="process manifest objects into the cache")
    p.add_argument("--manifest", required=True, help="manifest file (JSONL) of the objects to process")
    p.add_argument("--config", default=None, help="YAML processing config (ProcessConfig fields)")
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
    from datagen import _bounded

    from .errors import check_manifest_file

    check_manifest_file(args.manifest)  # refused before the imports below
    if args.config:
        _bounded.check_regular(args.config, _bounded.CONFIG_BYTES, "processing config")
    from .config import ProcessConfig
    from .prepare import DEFAULT_TIMEOUT_S, prepare, summarize, write_results

    cfg = ProcessConfig.from_yaml(args.config) if args.config else ProcessConfig()
    results = prepare(args.manifest, cfg, args.cache, args.workers, progress=True, limit=args.limit,
                      timeout_s=DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout)
    if args.results:
        write_results(results, args.results)
    print(summarize(results, args.results))
    return 0
