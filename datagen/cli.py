"""The ``datagen`` command line: argparse subcommands registered from each package.

To add a subcommand, write ``register(sub)`` in your package (it calls ``sub.add_parser`` and
sets ``func`` to a handler taking the parsed args and returning an exit code, and ``interrupted``
to what a Ctrl-C leaves and how to go on, formatted with the parsed args: see `interrupted_line`)
and add one line to ``REGISTRARS`` (a library package) or an entry point of group `PLUGIN_GROUP`
in pyproject.toml (the job commands of `workers/`, a layer above the library, which the library
never names). Only the registrar of the command being run is imported (all of them for
``datagen --help``), so one package's heavy imports never slow another's subcommand. Every
option has a help text; the help shows its default (`HelpFormatter`).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

import datagen

__all__ = ["PLUGIN_GROUP", "REGISTRARS", "registrars", "HelpFormatter", "Parser", "build_parser", "install_log_handler", "interrupted_line", "main"]

# subcommand name -> "module:function" registering it
REGISTRARS: dict[str, str] = {
    "hands": "datagen.listing:register_hands",
    "tasks": "datagen.listing:register_tasks",
    "manifest": "datagen.objects.commands:register_manifest",
    "prepare": "datagen.pipeline.commands:register_prepare",
    "hand": "datagen.pipeline.commands:register_hand",
    "synth": "datagen.pipeline.commands:register_synth",
    "eval": "datagen.eval.commands:register_eval",
    "render": "datagen.eval.commands:register_render",
    "export": "datagen.interop.commands:register_export",
    "import": "datagen.interop.commands:register_import",
    "view": "datagen.view.commands:register_view",
}
# Commands of the layers above the library (the job commands of `workers/`) plug in through the
# entry points of this group (pyproject.toml): the library never names them.
PLUGIN_GROUP = "datagen.commands"
# domain errors printed as one line with exit status 2 (module:class, looked up only if imported);
# every `datagen.errors.DatagenError` is one too
_ERRORS = ("datagen.gl:GLUnavailable",)


def registrars() -> dict[str, str]:
    """Subcommand name -> "module:function": the library's `REGISTRARS`, then the plugins'."""
    from importlib.metadata import entry_points

    return {**REGISTRARS, **{ep.name: ep.value for ep in entry_points(group=PLUGIN_GROUP) if ep.name not in REGISTRARS}}


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Appends ``(default: X)`` to an option's help unless the default is None/False (the help then
    says what happens) or the help already names it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default in (None, False, argparse.SUPPRESS) or "default" in text:
            return text
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose sub-parsers inherit `HelpFormatter`."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)


def build_parser(commands: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser with the subcommands ``commands`` registered (default: all)."""
    parser = Parser(prog="datagen", description="dexterous grasp dataset factory: synthesize hand poses, "
                    "check them in MuJoCo, write Parquet datasets. `datagen COMMAND -h` for a command's options.")
    parser.add_argument("--version", action="version", version=f"datagen {datagen.__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)
    for name, target in registrars().items():
        if commands is None or name in commands:
            module, _, func = target.partition(":")
            getattr(importlib.import_module(module), func)(sub)
    return parser


def _command(argv: list[str]) -> list[str] | None:
    """The subcommand named in ``argv`` (to register only it), [] for a bare ``--version``, None
    (register all) otherwise."""
    first = next((a for a in argv if not a.startswith("-")), None)
    if first in registrars():
        return [first]
    if first is None and "--version" in argv and not {"-h", "--help"} & set(argv):
        return []
    return None


def _domain_errors() -> tuple[type[BaseException], ...]:
    from datagen.errors import DatagenError

    out: list[type[BaseException]] = [ValueError, FileNotFoundError, DatagenError]
    for target in _ERRORS:
        module, _, name = target.partition(":")
        if module in sys.modules:  # a module never imported cannot have raised its error
            out.append(getattr(sys.modules[module], name))
    return tuple(out)


class _StderrHandler(logging.StreamHandler):
    """Writes to the current ``sys.stderr`` (not the one at creation: tests and front ends swap it)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass

    def format(self, record: logging.LogRecord) -> str:
        return f"datagen: {record.levelname.lower()}: {record.getMessage()}"


def install_log_handler() -> None:
    """The command line's one logging handler: the library's warnings and errors (logger
    ``datagen`` and its children) on stderr as ``datagen: warning: ...``. Installed once."""
    logger = logging.getLogger("datagen")
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        handler = _StderrHandler()
        handler.setLevel(logging.WARNING)
        logger.addHandler(handler)


def interrupted_line(args: argparse.Namespace | None, argv: list[str]) -> str:
    """The one line a Ctrl-C prints: the command, ``interrupted``, and its ``interrupted`` default
    (what was kept, how to go on) formatted with the parsed arguments."""
    command = args.command if args is not None else next((a for a in argv if a in registrars()), "")
    what = getattr(args, "interrupted", None)
    if what:
        what = what.format(**vars(args))
    else:  # interrupted while parsing or importing: nothing has been done yet
        what = "nothing was done; rerun the command"
    return f"datagen{' ' + command if command else ''}: interrupted; {what}"


def main(argv: list[str] | None = None) -> int:
    """Run one command; its exit code. A domain error is one line and exit 2; Ctrl-C is one line
    (`interrupted_line`) and exit 130, the shell's code for SIGINT (SIGTERM: "terminated", 143).
    Outputs are written atomically (`datagen._atomic`), so an interrupted command leaves no
    half-written file."""
    from datagen._interrupt import Terminated, raise_on_sigterm, was_terminated
    from datagen.gl import drop_unusable

    install_log_handler()
    raise_on_sigterm()

    drop_unusable()  # a MUJOCO_GL that would make `import mujoco` fail is dropped, with a warning
    argv = sys.argv[1:] if argv is None else list(argv)
    args = None
    try:
        args = build_parser(_command(argv)).parse_args(argv)
        try:
            return int(args.func(args) or 0)
        except _domain_errors() as exc:
            print(f"datagen {args.command}: error: {exc}", file=sys.stderr)
            return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (`Terminated`)
        line = interrupted_line(args, argv)
        terminated = isinstance(exc, Terminated) or was_terminated()
        if terminated:
            line = line.replace(": interrupted;", ": terminated (SIGTERM);", 1)
        print("\n" + line, file=sys.stderr)  # after a progress bar's line
        return 143 if terminated else 130
    except BrokenPipeError:  # stdout closed early (`datagen hands | head -1`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit's flush
        return 141  # the shell's code for SIGPIPE, as a command killed by it


if __name__ == "__main__":
    sys.exit(main())
