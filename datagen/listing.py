"""``datagen hands`` and ``datagen tasks``: what ``--hand`` and ``--task``/``--tasks`` accept."""

from __future__ import annotations

import argparse
import importlib.util
import re
from pathlib import Path

__all__ = ["HAND_DESCRIPTIONS", "hand_rows", "register_hands", "register_tasks", "task_rows"]

HAND_DESCRIPTIONS = {
    "shadow": "Shadow Dexterous Hand, gymnasium-robotics MJCF: 24 joints, 5 fingers, coupled distal joints",
    "leap": "LEAP Hand, MuJoCo Menagerie MJCF: 16 joints, 4 fingers",
    "allegro": "Allegro Hand (right), MuJoCo Menagerie MJCF: 16 joints, 4 fingers",
    "shadow_e3m5": "Shadow Hand E3M5 (right), MuJoCo Menagerie MJCF: 24 joints with wrist, 5 fingers",
}


def hand_rows() -> list[tuple[str, str, str]]:
    """(name, 'installed' or how to install it, description) of every built-in hand."""
    from datagen.hands.load import BUILTIN_HANDS

    rows = []
    for name, (_, package) in BUILTIN_HANDS.items():
        here = importlib.util.find_spec(package) is not None
        rows.append((name, "installed" if here else f"needs {package} (make hands)",
                     HAND_DESCRIPTIONS.get(name, f"asset from the {package} package")))
    return rows


def _first_sentence(path: Path) -> str:
    """The first sentence of a YAML file's leading comment block."""
    words = []
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        words.append(line.lstrip("#").strip())
    text = " ".join(w for w in words if w)
    end = re.search(r"\.\s+[A-Z]", text)  # "i.e. force" is not a sentence end
    return text if end is None else text[:end.start() + 1]


def task_rows() -> list[tuple[str, str, str]]:
    """(name, the object it runs on or 'any object', description) of every built-in task."""
    import yaml

    from datagen.tasks.spec import SPEC_DIR as TASK_DIR, builtin_tasks

    rows = []
    for name in builtin_tasks():
        path = TASK_DIR / f"{name}.yaml"
        ev = (yaml.safe_load(path.read_text()) or {}).get("eval")
        obj = ev.get("object") if isinstance(ev, dict) else None
        rows.append((name, f"object {obj}" if obj else "any object", _first_sentence(path)))
    return rows


def _print(rows: list[tuple[str, str, str]]) -> None:
    w0, w1 = (max(len(r[i]) for r in rows) for i in (0, 1))
    for a, b, c in rows:
        print(f"{a:<{w0}}  {b:<{w1}}  {c}")


def register_hands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("hands", help="list the built-in hands (--hand NAME; a hand spec YAML path works too)")
    p.set_defaults(func=lambda args: _print(hand_rows()) or 0, interrupted="nothing was written")


def register_tasks(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("tasks", help="list the built-in tasks (--task/--tasks NAME; a task YAML path works too)")
    p.set_defaults(func=lambda args: _print(task_rows()) or 0, interrupted="nothing was written")
