"""The ``datagen`` command line: argparse subcommands registered from each package.

To add a subcommand, write ``register(sub)`` in your package (it calls ``sub.add_parser`` and
sets ``func`` to a handler taking the parsed args and returning an exit code) and add one
line to ``REGISTRARS``. Registrars are imported lazily, so one package's heavy imports never
slow another's subcommand.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from datagen.objects.errors import ObjectError

__all__ = ["REGISTRARS", "build_parser", "main"]

# subcommand name -> "module:function" registering it (synth, eval, run, status, report later)
REGISTRARS: dict[str, str] = {
    "manifest": "datagen.objects.commands:register_manifest",
    "prepare": "datagen.objects.commands:register_prepare",
    "synth": "datagen.synth.commands:register_synth",
    "eval": "datagen.eval.commands:register_eval",
    "render": "datagen.eval.commands:register_render",
    "run": "workers.cli:register_run",
    "status": "workers.cli:register_status",
    "report": "workers.cli:register_report",
    "view": "datagen.view.commands:register_view",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="datagen", description="dexterous grasp dataset factory")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, target in REGISTRARS.items():
        module, _, func = target.partition(":")
        getattr(importlib.import_module(module), func)(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ObjectError, ValueError, FileNotFoundError) as exc:
        print(f"datagen {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
