"""Helpers shared by the benchmarks: timing medians and the machine description."""

from __future__ import annotations

import os
import platform
import statistics
import time

import torch


def median_time(fn, repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def machine_description() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = ""
    try:
        with open("/proc/meminfo") as f:
            mem = f"{int(f.readline().split()[1]) / 2**20:.0f} GiB RAM"
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "no GPU"
    return (f"{cpu}; {os.cpu_count()} cores; {mem}; {gpu}; torch {torch.__version__} "
            f"({torch.get_num_threads()} threads); Python {platform.python_version()}; load avg at start {load:.2f}")


def write_report(path, lines: list[str], echo: bool = True) -> None:
    """Write a benchmark's markdown ``lines`` to ``path`` (its folder made) and, by default, print them."""
    from pathlib import Path

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    if echo:
        print("\n".join(lines))


def hand_notes(path, heading: str = "## Notes") -> list[str]:
    """The hand-written section of a report (from ``heading`` up to a machine-readable fenced
    block or the end), for a benchmark that rewrites the report to keep; [] if there is none."""
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        return []
    lines = path.read_text().splitlines()
    start = next((i for i, x in enumerate(lines) if x.startswith(heading)), None)
    if start is None:
        return []
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("```")), len(lines))
    return lines[start:end]


def replace_section(path, heading: str, lines: list[str], first: bool = False) -> None:
    """Write ``lines`` (starting with the ``## `` ``heading``) as that section of the markdown page at
    ``path``: the old section (up to the next ``## `` heading) is replaced, the page's other sections
    are kept; a new section goes first (after the page title) when ``first``, else last."""
    from pathlib import Path

    path = Path(path)
    old = path.read_text().splitlines() if path.is_file() else []
    title = [old.pop(0), ""] if old and old[0].startswith("# ") else ["# " + path.stem.capitalize(), ""]
    while old and not old[0].strip():
        old.pop(0)
    sections, cur = [], []
    for line in old:
        if line.startswith("## ") and cur:
            sections.append(cur)
            cur = []
        cur.append(line)
    if cur:
        sections.append(cur)
    sections = [s for s in sections if s[0].strip() != heading.strip()]
    new = list(lines) + ([""] if lines and lines[-1].strip() else [])
    sections = [new, *sections] if first else [*sections, new]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(title + [x for s in sections for x in s]).rstrip("\n") + "\n")
