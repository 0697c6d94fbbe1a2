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
