"""The library's one-way flow (ARCHITECTURE.md): no module imports a layer above or beside it.

Read from the source (every ``import``, including those inside functions), so a lazy import that
runs back up fails here too."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# rank of each top-level part of `datagen`; a module may import only strictly lower ranks
# (and its own package). The root `datagen/__init__.py` is the curated facade over all of them.
RANK = {
    "errors": 0, "_bounded": 0.5,  # bounded reads of user files: only errors below it, config above
    "config": 1, "_atomic": 1, "_interrupt": 1, "rotation": 1, "scatter": 1, "gl": 1,
    "wrench": 2, "hands": 2, "objects": 2,
    "tasks": 3, "io": 3,
    "synth": 4, "eval": 4,
    "interop": 5, "pipeline": 5,
    "view": 6, "cli": 6, "listing": 6,
}


def _imports(path: Path) -> set[str]:
    parts = path.relative_to(ROOT).with_suffix("").parts
    pkg_parts = parts[:-1] if path.name != "__init__.py" else parts[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = list(pkg_parts[:len(pkg_parts) - node.level + 1])
                out.add(".".join(base + ([node.module] if node.module else [])))
            elif node.module:
                out.add(node.module)
    return out


def _library_modules():
    return sorted(p for p in (ROOT / "datagen").rglob("*.py") if p != ROOT / "datagen" / "__init__.py")


@pytest.mark.parametrize("path", _library_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_import_runs_up_or_sideways(path):
    part = path.relative_to(ROOT / "datagen").parts[0].removesuffix(".py")
    assert part in RANK, f"{part} has no layer: add it to RANK here and to ARCHITECTURE.md"
    for name in _imports(path):
        top = name.split(".")[0]
        assert top not in ("workers", "benchmarks", "tests"), f"{path}: library imports {name}"
        if top != "datagen" or name == "datagen":
            continue
        other = name.split(".")[1]
        if other == part:
            continue
        assert other in RANK, f"{path} imports {name}: unknown layer"
        assert RANK[other] < RANK[part], f"{path} ({part}, layer {RANK[part]}) imports {name} (layer {RANK[other]})"


# Front ends print to the user; library modules log through logging.getLogger("datagen....").
FRONT_ENDS = {"cli.py", "commands.py", "make_spec.py", "listing.py", "__main__.py"}
# `python -m datagen.gl` prints the backend it picked (its main()), `python -m datagen.pipeline.reference`
# the configuration page; the rest of those modules logs
CLI_MAINS = {"datagen/gl/__init__.py", "datagen/pipeline/reference.py"}
PENDING: set[str] = set()  # modules allowed to print for now (none)


@pytest.mark.parametrize("path", _library_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_library_modules_log_instead_of_printing(path):
    if path.name in FRONT_ENDS or str(path.relative_to(ROOT)) in PENDING | CLI_MAINS:
        return
    calls = [n for n in ast.walk(ast.parse(path.read_text()))
             if isinstance(n, ast.Call) and getattr(n.func, "id", None) == "print"
             or isinstance(n, ast.Call) and getattr(n.func, "attr", None) == "warn"
             and getattr(n.func.value, "id", None) == "warnings"]
    assert not calls, f"{path}:{calls[0].lineno}: print/warnings.warn in library code; use logging.getLogger(__name__)"


def test_the_curated_api_resolves_lazily():
    import subprocess
    import sys

    import datagen

    code = "import sys, datagen; assert 'torch' not in sys.modules and 'mujoco' not in sys.modules"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr  # import datagen stays light
    assert len(datagen.__all__) >= 10
    for name in datagen.__all__:
        assert getattr(datagen, name) is not None, name


@pytest.mark.parametrize("path", _library_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_library_module_names_a_module_of_the_layers_above(path):
    """Not even as a string (an import by name, a registrar): the job commands plug in through the
    entry points of `datagen.cli.PLUGIN_GROUP` in pyproject.toml."""
    import re

    strings = [n.value for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.Constant)
               and isinstance(n.value, str)]
    named = [s for s in strings if re.match(r"^(workers|benchmarks)\.[a-z_]+(:|$)", s)]
    assert not named, f"{path} names {named}"


def test_the_job_commands_plug_into_the_command_line():
    from datagen.cli import registrars

    assert {"run", "status", "verify", "report"} <= set(registrars())
    assert registrars()["run"] == "workers.cli:register_run"
