"""CLI: ``datagen run``, ``datagen status JOB_DIR``, ``datagen report JOB_DIR``."""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["register_run", "register_status", "register_report"]


def register_run(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run or resume a dataset job (Ray)")
    p.add_argument("--out", default="jobs/default", help="job directory (created; resumed if it exists)")
    p.add_argument("--config", default=None, help="YAML of JobConfig fields (flags below override it)")
    p.add_argument("--objects", type=int, default=None, dest="count",
                   help="number of objects (JobConfig.count; default 6). Not an object size: object sizes "
                        "are JobConfig.scales, metres")
    p.add_argument("--scale", type=_renamed_scale, default=None, help=argparse.SUPPRESS)
    p.add_argument("--source", default=None, help="object source URI: procedural, tasks, dir:PATH, dexgraspnet:PATH, pybullet "
                   "(default: procedural)")
    p.add_argument("--manifest", default=None, help="existing manifest; its first --objects objects are used")
    p.add_argument("--hand", default=None, help="built-in hand name (`datagen hands`) or hand spec YAML "
                   "(default: shadow)")
    p.add_argument("--tasks", default=None, help="comma-separated task names (`datagen tasks`) or YAML paths "
                   "(default: force_closure)")
    p.add_argument("--grasps", type=int, default=None, help="grasps per object and scale (default: 8)")
    p.add_argument("--objects-per-shard", type=int, default=None, help="objects per shard task (default: 2)")
    p.add_argument("--seed", type=int, default=None, help="base seed; shard k synthesizes with seed + k (default: 0)")
    p.add_argument("--address", default=None, help="Ray cluster address (default $RAY_ADDRESS, else local)")
    p.add_argument("--num-cpus", type=int, default=None, help="local Ray CPUs (default: all cores)")
    p.add_argument("--cache", default=None, help="objects cache root (default $DATAGEN_CACHE)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_run)


def _renamed_scale(value: str):
    raise argparse.ArgumentTypeError(f"`datagen run --scale` was renamed `--objects` (a number of objects: "
                                     f"--objects {value}); object sizes in metres are JobConfig.scales")


def _config(args):
    import yaml

    from .job import JobConfig

    data = yaml.safe_load(open(args.config)) if args.config else {}
    data = dict(data or {})
    for key, val in (("count", args.count), ("source", args.source), ("manifest", args.manifest),
                     ("hand", args.hand), ("grasps_per_object", args.grasps),
                     ("objects_per_shard", args.objects_per_shard), ("seed", args.seed)):
        if val is not None:
            data[key] = val
    if args.tasks:
        data["tasks"] = [t.strip() for t in args.tasks.split(",") if t.strip()]
    return JobConfig.from_dict(data, where=args.config or "command line")


def _run(args) -> int:
    from .job import JobError
    from .run import run_job
    from .status import format_status

    try:
        status = run_job(_config(args), args.out, address=args.address, num_cpus=args.num_cpus,
                         cache=args.cache, progress=not args.no_progress)
    except JobError as exc:
        print(f"datagen run: error: {exc}", file=sys.stderr)
        return 2
    print(format_status(status))
    return 0 if status["complete"] else 1


def register_status(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("status", help="progress and outcomes of a job directory")
    p.add_argument("job", help="job directory")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_status)


def _status(args) -> int:
    from .job import JobError
    from .status import format_status, job_status

    try:
        s = job_status(args.job)
    except JobError as exc:
        print(f"datagen status: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(s, indent=1) if args.json else format_status(s))
    return 0


def register_report(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="write a dataset card (JOB_DIR/README.md) with rendered grasps")
    p.add_argument("job", help="job directory")
    p.add_argument("--renders", type=int, default=6,
                   help="grasps to draw, successes and failures alternately, across objects (0: none)")
    p.set_defaults(func=_report)


def _report(args) -> int:
    from .job import JobError
    from .report import write_report

    try:
        path = write_report(args.job, renders=args.renders)
    except JobError as exc:
        print(f"datagen report: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0
