"""CLI: ``datagen run``, ``datagen status JOB_DIR``, ``datagen verify JOB_DIR``, ``datagen report JOB_DIR``."""

from __future__ import annotations

import argparse
import json
import sys

from datagen.pipeline.commands import add_recipe_arguments, recipe_flags

__all__ = ["register_run", "register_status", "register_report", "register_verify"]


def register_run(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="run or resume a dataset job (Ray)")
    p.add_argument("--out", default="jobs/default", help="job directory (created; resumed if it exists)")
    p.add_argument("--config", default=None, help="YAML of JobConfig fields (flags below override it)")
    p.add_argument("--resume", action="store_true",
                   help="resume the job in --out with the config its job.json records (no --config needed; flags "
                        "may change only the execution settings, e.g. --object-timeout)")
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
    p.add_argument("--grasps", type=int, default=None, help="grasps per object and scale (default: 16)")
    p.add_argument("--objects-per-shard", type=_per_shard, default=None, metavar="N|auto",
                   help="objects per shard task, or auto (the default): chosen for the object count and the "
                        "worker slots when the job is created, e.g. 3 for the default 6 objects on 2 cores")
    p.add_argument("--seed", type=int, default=None, help="base seed; shard k synthesizes with seed + k (default: 0)")
    add_recipe_arguments(p)
    p.add_argument("--address", default=None, help="Ray cluster address (default $RAY_ADDRESS, else local)")
    p.add_argument("--num-cpus", type=int, default=None, help="local Ray CPUs (default: all cores; at least 1)")
    p.add_argument("--cache", default=None, help="objects cache root (default $DATAGEN_CACHE)")
    p.add_argument("--object-timeout", type=float, default=None, metavar="SECONDS",
                   help="per-object processing limit (JobConfig.object_timeout_s, default 300); an execution "
                        "setting: a resumed job may change it")
    p.add_argument("--retry-failed", action="store_true",
                   help="also rerun finished shards with failures a rerun may fix (timeout, crashed, error, "
                        "missing_file, ...); failures decided by a mesh's bytes are final")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    # Ctrl-C (datagen.cli.main): running shards are abandoned with Ray's shutdown; their files are
    # written atomically and only a ledger entry marks a shard finished, so a rerun redoes exactly
    # the unfinished ones
    p.set_defaults(func=_run, interrupted="rerun the same command to resume")


def _per_shard(value: str):
    if value == "auto":
        return value
    try:
        return int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer or 'auto', got {value!r}") from None


def _renamed_scale(value: str):
    raise argparse.ArgumentTypeError(f"`datagen run --scale` was renamed `--objects` (a number of objects: "
                                     f"--objects {value}); object sizes in metres are JobConfig.scales")


def _config(args):
    from datagen.config import read_yaml

    from .job import JobConfig, JobError

    if args.resume:
        if args.config:
            raise JobError("--resume takes the job's config from its job.json: drop --config")
        from .job import JobDir

        data = JobDir(args.out).read_job()["config"]
    else:
        try:
            data = read_yaml(args.config, "job config") if args.config else {}
        except ValueError as exc:
            raise JobError(str(exc)) from None
    if data is not None and not isinstance(data, dict):
        raise JobError(f"{args.config}: a job config must be a mapping of JobConfig fields")
    data = dict(data or {})
    for key, val in (("count", args.count), ("source", args.source), ("manifest", args.manifest),
                     ("hand", args.hand), ("grasps_per_object", args.grasps),
                     ("objects_per_shard", args.objects_per_shard), ("seed", args.seed),
                     ("object_timeout_s", args.object_timeout)):
        if val is not None:
            data[key] = val
    if args.tasks:
        data["tasks"] = [t.strip() for t in args.tasks.split(",") if t.strip()]
    flags = recipe_flags(args)
    if "preset" in flags:
        data["preset"] = flags["preset"]
    if "grasp_types" in flags:
        data["grasp_types"] = flags["grasp_types"]
    if "scene" in flags:  # --scene / --stable-poses over the config's scene (a name or a mapping)
        base = data.get("scene")
        base = {"kind": base} if isinstance(base, str) else dict(base or {})
        data["scene"] = {**base, **flags["scene"]}
    if "synth" in flags:
        if data.get("synth") is not None and not isinstance(data["synth"], dict):
            raise JobError(f"{args.config}: synth must be a mapping of SynthConfig fields")
        data["synth"] = {**(data.get("synth") or {}), **flags["synth"]}
    where = f"{args.out}/job.json" if args.resume else args.config or "command line"
    return JobConfig.from_dict(data, where=where)


def closing_summary(status: dict) -> str:
    """Where the data is and what to run next, printed at the end of ``datagen run``."""
    from pathlib import Path

    job = Path(status["job"])
    shards = sorted((job / "shards").glob("part-*.parquet"))
    lines = []
    if shards:
        names = shards[0].name if len(shards) == 1 else f"{shards[0].name} .. {shards[-1].name}"
        lines.append(f"data: {len(shards)} Parquet shard{'s' * (len(shards) > 1)} in {job / 'shards'} ({names}); "
                     f"failures in {job / 'failures.parquet'}")
    else:
        lines.append(f"data: no grasp rows yet in {job / 'shards'}; failures in {job / 'failures.parquet'}")
    if not status["complete"]:
        lines.append(f"incomplete: {status['shards_done']}/{status['shards_total']} shards; rerun the same command "
                     "to resume")
    elif status.get("retryable"):
        lines.append(f"{status['retryable']} shard(s) have failures a rerun may fix: rerun with --retry-failed")
    lines += [f"dataset card:  datagen report {job}",
              f"status:        datagen status {job}",
              "read it:       python -c \"from datagen.io import read_job; "
              f"t = read_job('{job}', only_success=True); print(t.num_rows, t.column_names[:4])\"",
              f"   or pandas: pandas.read_parquet('{job / 'shards'}')"]
    return "\n".join(lines)


def _check_inputs(args) -> None:
    """--config and --manifest are regular files within their caps: a device or a FIFO is refused
    at once, before the imports of a job (torch, Ray: seconds)."""
    from datagen import _bounded
    from datagen.objects.errors import check_manifest_file

    if args.config:
        _bounded.check_regular(args.config, _bounded.CONFIG_BYTES, "job config")
    if args.manifest:
        check_manifest_file(args.manifest)


def _run(args) -> int:
    _check_inputs(args)
    from .job import JobError
    from .run import run_job
    from .status import format_status

    try:
        status = run_job(_config(args), args.out, address=args.address, num_cpus=args.num_cpus,
                         cache=args.cache, progress=not args.no_progress, retry_failed=args.retry_failed)
    except JobError as exc:
        print(f"datagen run: error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)  # 1 for a job that could not write (JobIOError)
    print(format_status(status))
    print(closing_summary(status))
    return 0 if status["complete"] else 1


def register_status(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("status", help="progress and outcomes of a job directory")
    p.add_argument("job", help="job directory")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--diversity", action="store_true",
                   help="also the successes' diversity per task and scale (PCA explained variance, joint entropy)")
    p.set_defaults(func=_status, interrupted="nothing was written")


def _status(args) -> int:
    from datagen.io import ShardError

    from .job import JobError
    from .status import format_diversity, format_status, job_diversity, job_status

    try:
        s = job_status(args.job)
        if args.diversity:
            s["diversity"] = job_diversity(args.job)
    except JobError as exc:
        print(f"datagen status: error: {exc}", file=sys.stderr)
        return 2
    except ShardError as exc:
        print(f"datagen status: error: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(s, indent=1))
    else:
        print(format_status(s) + ("\n" + format_diversity(s["diversity"]) if args.diversity else ""))
    return 0


def register_verify(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("verify", help="check every file of a job against the sha256 its ledger records")
    p.add_argument("job", help="job directory")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_verify, interrupted="nothing was written")


def _verify(args) -> int:
    from .job import JobError
    from .verify import format_verify, verify_job

    try:
        v = verify_job(args.job)
    except JobError as exc:
        print(f"datagen verify: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(v, indent=1) if args.json else format_verify(v))
    return 1 if v["problems"] or v["manifest"] else 0


def register_report(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="write a dataset card (JOB_DIR/README.md) with rendered grasps")
    p.add_argument("job", help="job directory")
    p.add_argument("--renders", type=int, default=6,
                   help="grasps to draw, successes and failures alternately, across objects (0: none)")
    p.set_defaults(func=_report, interrupted="{job}/README.md is unchanged (pictures already drawn are kept in "
                   "{job}/renders); rerun the same command")


def _report(args) -> int:
    from .job import JobError
    from .report import write_report

    try:
        path = write_report(args.job, renders=args.renders)
    except JobError as exc:
        print(f"datagen report: error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_code", 2)
    print(f"wrote {path}")
    return 0
