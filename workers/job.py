"""A job directory: its config, lock, manifest slice, shard layout and ledger of finished shards.

The directory's layout is `datagen.io.layout`'s (one owner: the readers share it); job.json here
records the full JobConfig, its resolved recipes and hash, code and package versions. Ray's temp
dir is ``ray/`` when the path is short enough (else /tmp/dg-ray-*, `workers.cluster`).

A job is resumable: re-running the same config skips the shards with a ledger entry and redoes
the others (their outputs are overwritten atomically). A different config is refused; the
execution settings (`EXECUTION_FIELDS`: object time limit, resources per shard) may change.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import hashlib
import json
import os
import platform
import re
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Mapping


from datagen import _bounded
from datagen._atomic import atomic_write_text
from datagen.io import integrity
from datagen.objects.manifest import NATIVE
from datagen.objects.observations import ObservationConfig
from datagen.config import Config, check_types
from datagen.errors import ConfigError, DatagenError
from datagen.pipeline.recipe import DEFAULT_PRESET, resolve
from datagen.io.layout import (FAILURES, FAILURES_DIR, JOB_JSON, LEDGER_DIR, LOCK, MANIFEST, MANIFEST_FAILURES,
                               MANIFEST_RECORD, OBJECTS_DIR, OBSERVATIONS_DIR, PROGRESS_DIR, SHARD_NAME, SHARDS_DIR)

__all__ = ["AUTO", "EXECUTION_FIELDS", "JobConfig", "JobDir", "JobError", "JobIOError", "code_version",
           "package_versions", "shard_size", "shard_slices", "writing"]




class JobError(DatagenError, RuntimeError):
    """A job that cannot start or go on (names the job directory and the reason)."""


class JobConfigError(ConfigError, JobError):
    """A malformed job config (unknown key, wrong type), from the config helper: a `JobError`."""


class JobIOError(JobError):
    """A job file that cannot be written (a full disk, a quota, a read-only file system): not a
    usage error, so the command exits 1. Names the path, the cause and the remedy."""

    exit_code = 1


def _errno_of(exc) -> int | None:
    """The errno of an OSError, also of pyarrow's (which carry it only in their text)."""
    code = getattr(exc, "errno", None)
    if isinstance(code, int):
        return code
    m = re.search(r"\[errno (\d+)\]", str(exc), re.I)
    return int(m.group(1)) if m else None


@contextlib.contextmanager
def writing(path: str | Path, what: str = "the job file"):
    """Turn an OSError raised while writing ``path`` into a `JobIOError` naming it (one line: the
    path, the cause, what to do). The writes under it are atomic: nothing half-written stays."""
    try:
        yield
    except OSError as exc:
        code = _errno_of(exc)
        cause = os.strerror(code) if code else " ".join(str(exc).split())
        if code in (errno.ENOSPC, errno.EDQUOT):
            remedy = (f"free space on the file system holding {Path(path).parent} (`df -h {Path(path).parent}`) "
                      "and rerun the same command: finished shards are kept, the others are redone")
        elif code == errno.EROFS:
            remedy = "the file system is read-only: choose another --out"
        else:
            remedy = "fix the permissions or choose another --out, then rerun the same command"
        raise JobIOError(f"cannot write {what} {path}: {cause}", remedy) from None


# fields that say how a job runs, not what it produces: outside the config hash, so a resumed
# job may change them (a longer object timeout, more CPUs per shard)
EXECUTION_FIELDS = ("object_timeout_s", "cpus_per_shard", "gpus_per_shard")
# fields that are layers of the recipes: hashed through the resolved recipes they give (a job made
# with the preset's values spelled out is the same job)
RECIPE_FIELDS = ("preset", "synth", "eval", "process", "grasp_types", "grid_resolution", "scene")
MAX_SEED = 2**62                        # shard k uses seed + k; int64 columns hold it
MAX_GRASPS_PER_OBJECT = 10_000
AUTO = "auto"                           # objects_per_shard chosen at the job's creation (`shard_size`)
PREFERRED_PER_SHARD = 2                 # 4 targets (2 objects x 2 scales) per synthesis: its cheapest batch
MAX_AUTO_PER_SHARD = 4                  # at most this many objects in an automatically sized shard
SINGLE_OBJECT_COST = 1.16               # synthesis cost per grasp of a 1-object shard (2 targets) over 2 objects'
GPU_AUTO_PER_SHARD = 16                 # on GPUs: one batch of 32 targets, 15.0 s for 512 grasps on an H200, against
                                        # 33.2 s for 192 grasps in 3 batches of 4 targets (cuda_check.md, 2026-11-27)


@dataclass(frozen=True)
class JobConfig(Config):
    """Everything that determines a job's rows (hashed: any change is a different job), plus the
    execution settings of `EXECUTION_FIELDS` (not hashed). From a mapping or YAML through the
    config helper (`datagen.config`: unknown keys refused, types checked); bounds here."""

    config_error: ClassVar[type[ConfigError]] = JobConfigError

    source: str = "procedural"          #: object source URI (datagen.objects.sources)
    count: int = 6                      #: objects (SCALE)
    scales: tuple[float | str, ...] = (0.06, 0.08)  #: object scales, metres, or "native" (the meshes' own
                                        #: size); of a built manifest: a given manifest's own scales are used

    test_fraction: float = 0.1          #: manifest split
    manifest: str = ""                  #: existing manifest file (its first `count` objects); "" = build
    hand: str = "shadow"                #: built-in hand name or hand spec YAML path
    tasks: tuple[str, ...] | str = ("force_closure",)  #: built-in task names or task YAML paths (one: a string)
    grasps_per_object: int = 16         #: per object and scale (1 to 10000); 16: bench-pipeline's sweep
    objects_per_shard: int | str = AUTO  #: objects per shard task, or "auto": chosen when the job is
                                        #: created for its object count and the cluster's worker slots
                                        #: (`shard_size`); job.json records the number chosen
    seed: int = 0                       #: base seed, 0 <= seed < 2**62; shard k synthesizes with seed + k
    object_timeout_s: float = 300.0     #: per-object processing limit (isolated process); not hashed
    # what the grasps are made with: the recipe of each task (`datagen.pipeline.resolve`), from the
    # preset, the task's own synth block and these settings on top (unset keys: the preset's)
    preset: str = DEFAULT_PRESET        #: settings preset (datagen.pipeline.PRESETS: dataset, paper)
    synth: dict[str, Any] = field(default_factory=dict)  #: SynthConfig fields
    eval: dict[str, Any] = field(default_factory=dict)  #: EvalConfig fields
    process: dict[str, Any] = field(default_factory=dict)  #: ProcessConfig fields (CoACD, ...)
    grasp_types: dict[str, Any] | str | None = None  #: grasp type per object size (GraspMix bands, or one
                                        #: type's name; None: the preset's)
    grid_resolution: int | None = None  #: synthesis SDF grid nodes per axis, 8 to 256 (None: the preset's;
                                        #: 64: ~25 s/object on one core, 48: ~10 s, 32: ~3 s)
    scene: dict[str, Any] | str | None = None  #: floating or tabletop (a scene's name, or kind and
                                        #: stable_poses; None: the preset's, floating; docs/scenes.md)
    # what a learner sees of each object and scale, beside the shards (observations/part-NNNNN.parquet;
    # datagen.objects.observations; cost: docs/learning.md): surface points and normals by default
    observations: ObservationConfig = field(default_factory=ObservationConfig)  #: ObservationConfig fields
    cpus_per_shard: float = 1.0         #: Ray resources of one shard task; also its torch threads and
                                        #: its evaluation processes (not hashed: keep it fixed within a
                                        #: job for identical floats)
    gpus_per_shard: float = 1.0         #: used only when the cluster has GPUs

    def __post_init__(self):
        def need(ok: bool, what: str):
            if not ok:
                raise JobError(f"JobConfig.{what}")

        check_types(self)
        if isinstance(self.observations, Mapping):  # constructed in code with a mapping
            object.__setattr__(self, "observations", ObservationConfig.from_dict(self.observations, "observations"))
        if isinstance(self.tasks, str):
            object.__setattr__(self, "tasks", (self.tasks,))
        need(all(t for t in self.tasks), f"tasks must be names or paths, got {self.tasks!r}")
        need(all(s == NATIVE or (isinstance(s, (int, float)) and not isinstance(s, bool)) for s in self.scales),
             f"scales must be numbers (metres) or 'native', got {self.scales}")
        object.__setattr__(self, "scales", tuple(s if s == NATIVE else float(s) for s in self.scales))
        object.__setattr__(self, "tasks", tuple(self.tasks))
        need(self.count >= 1, f"count must be an int >= 1, got {self.count!r}")
        numeric = [s for s in self.scales if s != NATIVE]
        need(bool(self.scales) and all(0 < s < 10 for s in numeric),
             f"scales must be in (0, 10) metres, got {self.scales}")
        need(len(set(self.scales)) == len(self.scales), f"scales must be distinct, got {self.scales}")
        need(0 <= self.test_fraction <= 1, f"test_fraction must be in [0, 1], got {self.test_fraction}")
        need(bool(self.tasks), "tasks must name at least one task")
        need(len(set(self.tasks)) == len(self.tasks), f"tasks must be distinct, got {list(self.tasks)}")
        need(bool(self.hand), "hand must name a hand")
        need(1 <= self.grasps_per_object <= MAX_GRASPS_PER_OBJECT,
             f"grasps_per_object must be in 1..{MAX_GRASPS_PER_OBJECT}, got {self.grasps_per_object}")
        need(self.objects_per_shard == AUTO or (isinstance(self.objects_per_shard, int) and self.objects_per_shard >= 1),
             f"objects_per_shard must be an int >= 1 or {AUTO!r}, got {self.objects_per_shard!r}")
        need(0 <= self.seed < MAX_SEED, f"seed must be an int in [0, 2**62), got {self.seed}")
        need(self.object_timeout_s > 0, f"object_timeout_s must be > 0 seconds, got {self.object_timeout_s}")
        need(self.cpus_per_shard > 0 and self.gpus_per_shard >= 0, "cpus_per_shard must be > 0, gpus_per_shard >= 0")
        try:
            self.recipes()  # validates the settings now, not in a worker
        except (ValueError, TypeError) as exc:
            if not self._inputs_readable():
                return  # a task or hand spec this machine cannot read: `check_runnable` names it
            raise JobError(f"JobConfig: {exc}") from None

    def recipes(self) -> list:
        """The resolved `datagen.pipeline.Recipe` of each task, in ``tasks`` order (they share the
        process config and grid: the objects are processed once for all of them)."""
        layer = {"preset": self.preset, "synth": self.synth, "eval": self.eval, "process": self.process,
                 "grasp_types": self.grasp_types, "grid_resolution": self.grid_resolution, "scene": self.scene}
        return [resolve(self.hand, t, config=layer, where="job config") for t in self.tasks]

    def check_runnable(self):
        """Refuse (JobError naming the value and the valid ones) a hand or task this machine
        cannot load, or MuJoCo-rendered camera views without an offscreen GL backend, before any work starts;
        returns the loaded hand (`load_hand`). Not part of construction: ``datagen status`` reads
        job.json on machines that may lack a hand's asset package."""
        hand = self.load_hand()
        self.check_observations()
        from datagen.objects.errors import ObjectError
        from datagen.objects.manifest import load_manifest
        from datagen.objects.sources import canonical_source

        try:
            if self.manifest:
                load_manifest(self.manifest)
            else:
                kind, _, root = canonical_source(self.source).partition(":")
                if kind in ("dir", "dexgraspnet") and not Path(root).is_dir():
                    raise JobError(f"source {self.source!r}: {root} is not a folder")
        except ObjectError as exc:
            raise JobError(str(exc)) from None
        self.check_tasks()
        return hand

    def check_observations(self) -> None:
        """With camera views, resolve the depth renderer now (`resolve_renderer`: for MuJoCo's it
        chooses the offscreen GL backend and sets MUJOCO_GL, which the local Ray workers inherit);
        refuse (JobError) ``renderer: mujoco`` when no GL backend works (``auto`` casts rays then)."""
        if not self.observations.views:
            return
        from datagen.gl import GLUnavailable
        from datagen.objects.observations import resolve_renderer

        try:
            resolve_renderer(self.observations.renderer)
        except GLUnavailable as exc:
            raise JobError(f"observations.renderer is mujoco (depth images): {exc}",
                           "or set observations.renderer: auto, which ray-casts where no GL works") from None

    def _inputs_readable(self) -> bool:
        """Whether every task loads and the hand is a built-in name or an existing spec file."""
        from datagen.hands import BUILTIN_HANDS
        from datagen.tasks import load_task

        try:
            for t in self.tasks:
                load_task(t)
        except Exception:  # noqa: BLE001 - any task problem: the inputs are not readable here
            return False
        return self.hand in BUILTIN_HANDS or Path(self.hand).is_file()

    def check_tasks(self) -> None:
        """Refuse (JobError) a task that cannot be loaded: an unknown name with the valid ones, a
        bad task YAML with its first error."""
        from datagen.tasks import builtin_tasks, load_task

        for t in self.tasks:
            try:
                load_task(t)
            except Exception as exc:  # noqa: BLE001 - ConfigError, or a bad task YAML
                first = " ".join(str(exc).split())
                if Path(t).suffix:
                    raise JobError(f"task {t!r}: {first}") from None
                raise JobError(f"unknown task {t!r}; valid tasks: {', '.join(builtin_tasks())} "
                               "(or the path of a task YAML)") from None

    def load_hand(self):
        """The job's hand (`datagen.hands.HandModel`), loaded as a shard loads it: the spec read,
        its MJCF/URDF parsed and compiled by MuJoCo, the kinematic chain built and checked against
        MuJoCo's. Any problem is a `JobError` naming the hand, the file and the remedy, before the
        job directory exists (the issue-42 check up front)."""
        from datagen.hands import BUILTIN_HANDS, HandSpecError, available_hands, load_hand

        if self.hand in BUILTIN_HANDS:
            if self.hand not in available_hands():
                raise JobError(f"hand {self.hand!r}: its asset package is not installed; run `make hands` "
                               f"(installed hands: {available_hands()})")
        elif not (Path(self.hand).suffix.lower() in (".yaml", ".yml") and Path(self.hand).is_file()):
            raise JobError(f"unknown hand {self.hand!r}; valid hands: {', '.join(sorted(BUILTIN_HANDS))} "
                           "(or the path of a hand spec YAML)")
        try:
            return load_hand(self.hand)
        except HandSpecError as exc:
            raise JobError(f"hand {self.hand}: {exc}") from None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any] | None = None, where: str | None = "job config") -> "JobConfig":
        return super().from_dict(data, where)

    @classmethod
    def from_yaml(cls, path: str | Path) -> "JobConfig":
        """From a YAML mapping; tags, aliases and files over 1 MiB are refused (`read_yaml`)."""
        from datagen.config import read_yaml

        try:
            data = read_yaml(path, "job config")
        except ValueError as exc:
            raise JobError(str(exc)) from None
        return cls.from_dict(data, where=str(path))

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain data (job.json's ``config``); `from_dict` of it gives an equal config."""
        d = dataclasses.asdict(self)
        d["scales"], d["tasks"] = list(self.scales), list(self.tasks)
        return d

    def identity(self) -> dict[str, Any]:
        """The hashed part of `to_dict` (execution settings removed)."""
        d = self.to_dict()
        for k in EXECUTION_FIELDS:
            d.pop(k)
        return d

    def hash(self) -> str:
        """sha256 of the canonical JSON of `identity` and the resolved recipes (what decides the
        rows: a changed library default or task YAML is a different job too)."""
        config = {k: v for k, v in self.identity().items() if k not in RECIPE_FIELDS}
        doc = {"config": config, "recipes": [r.to_dict() for r in self.recipes()]}
        return hashlib.sha256(json.dumps(doc, sort_keys=True, default=list).encode()).hexdigest()


def code_version() -> str:
    """datagen's version plus the git commit (and '-dirty') when run from a checkout."""
    import datagen

    root = Path(__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                                text=True, timeout=5).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "", ""
    return datagen.__version__ + (f"+g{commit}" if commit else "") + ("-dirty" if dirty else "")


def package_versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for name in ("torch", "numpy", "mujoco", "coacd", "trimesh", "pyarrow", "ray", "pytorch-kinematics"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = ""
    return out


class JobDir:
    """Paths and bookkeeping of one job directory (see the module docstring)."""

    def __init__(self, path: str | Path):
        self.path = Path(path).resolve()
        self._lock_fh = None

    # ---------------------------------------------------------------- paths
    def shard_name(self, index: int) -> str:
        return SHARD_NAME.format(index=index)

    def shard_path(self, index: int) -> Path:
        return self.path / SHARDS_DIR / f"{self.shard_name(index)}.parquet"

    def observations_path(self, index: int) -> Path:
        return self.path / OBSERVATIONS_DIR / f"{self.shard_name(index)}.parquet"

    def shard_failures_path(self, index: int) -> Path:
        return self.path / FAILURES_DIR / f"{self.shard_name(index)}.parquet"

    def progress_path(self, index: int) -> Path:
        return self.path / PROGRESS_DIR / f"{self.shard_name(index)}.json"

    @property
    def manifest_failures_path(self) -> Path:
        return self.path / FAILURES_DIR / MANIFEST_FAILURES

    def ledger_path(self, index: int) -> Path:
        return self.path / LEDGER_DIR / f"{self.shard_name(index)}.json"

    @property
    def manifest_path(self) -> Path:
        return self.path / MANIFEST

    @property
    def manifest_record_path(self) -> Path:
        return self.path / LEDGER_DIR / MANIFEST_RECORD

    @property
    def failures_path(self) -> Path:
        return self.path / FAILURES

    @property
    def objects_dir(self) -> Path:
        return self.path / OBJECTS_DIR

    # ------------------------------------------------------------- lock
    def lock(self) -> None:
        """Take the job's exclusive lock (released when this process exits, even by SIGKILL)."""
        self.path.mkdir(parents=True, exist_ok=True)
        fh = open(self.path / LOCK, "a+")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            fh.close()
            raise JobError(f"job directory {self.path} is locked by {holder}: two jobs cannot share a "
                           "directory; wait for it to finish or use another --out") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()} on {socket.gethostname()}\n")
        fh.flush()
        self._lock_fh = fh

    def unlock(self) -> None:
        if self._lock_fh is not None:
            fcntl.flock(self._lock_fh, fcntl.LOCK_UN)
            self._lock_fh.close()
            self._lock_fh = None

    # ------------------------------------------------------------- config
    def read_job(self) -> dict:
        """job.json; `JobError` naming it (and the remedy) when it is missing, empty or truncated."""
        p = self.path / JOB_JSON
        if not p.is_file():
            raise JobError(f"{self.path} is not a job directory (no {JOB_JSON})")
        try:
            doc = _bounded.read_json(p, "job file")
            if not isinstance(doc, dict) or not isinstance(doc.get("config"), dict):
                raise _bounded.InputError(p, _bounded.NOT_TEXT, "the job file holds no job config")
        except _bounded.InputError as exc:
            hashes = sorted(self.recorded_hashes())
            known = f" (its shards record config hash {hashes[0][:12]})" if len(hashes) == 1 else ""
            raise JobError(str(exc), f"restore it from a copy, or rerun `datagen run --out {self.path}` with the job's "
                           f"original settings{known}: when they match what its shards record, {JOB_JSON} is "
                           "written again") from None
        return doc

    def config(self) -> JobConfig:
        return JobConfig.from_dict(self.read_job()["config"], where=str(self.path / JOB_JSON))

    def init(self, cfg: JobConfig) -> bool:
        """Write job.json, or check that the existing one has the same config hash.
        Returns True when resuming an existing job. ``objects_per_shard`` must be a number here
        (``run_job`` resolves "auto" first): job.json records the shard layout."""
        if cfg.objects_per_shard == AUTO:
            raise JobError(f"job {self.path}: objects_per_shard 'auto' must be resolved to a number before the "
                           "job is created (workers.run.run_job does it; or pass a number)")
        p = self.path / JOB_JSON
        if p.is_file() and self._repair_job_json(cfg):
            return True
        if p.is_file():
            old = self.read_job()
            if old.get("config_hash") != cfg.hash() and self._rehash(old) == cfg.hash():
                # made by an older version with the same resolved settings: same rows, record the new hash
                old["config_hash"] = cfg.hash()
                atomic_write_text(p, json.dumps(old, indent=1, sort_keys=True))
            if old.get("config_hash") != cfg.hash():
                new, was = cfg.identity(), dict(old.get("config", {}))
                diff = sorted(k for k in set(new) | set(was) if k not in EXECUTION_FIELDS and new.get(k) != was.get(k))
                added = [k for k in diff if k not in was]
                if added:  # fields a later version added: no settings of this version give that job
                    raise JobError(f"job directory {self.path} was made by datagen {old.get('code_version', '?')}, "
                                   f"before {', '.join(added)} existed (config hash "
                                   f"{str(old.get('config_hash'))[:12]} != {cfg.hash()[:12]}): a job cannot be "
                                   "resumed across that change; finish it with the version that made it, or run "
                                   "this one with another --out")
                diff = diff or ["the resolved recipes (a library default, preset or task YAML changed)"]
                raise JobError(f"job directory {self.path} holds a different job (config hash "
                               f"{str(old.get('config_hash'))[:12]} != {cfg.hash()[:12]}; fields differing: {diff}); "
                               "re-run with the same settings to resume, or use another --out")
            return True
        with writing(self.path / JOB_JSON):
            for d in (SHARDS_DIR, FAILURES_DIR, OBJECTS_DIR, LEDGER_DIR):
                (self.path / d).mkdir(parents=True, exist_ok=True)
            self._write_job_json(cfg, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
        return False

    def _write_job_json(self, cfg: JobConfig, created_at: str) -> None:
        recipes = cfg.recipes()
        doc = {"config": cfg.to_dict(), "recipes": [r.to_dict() for r in recipes],
               "config_hash": cfg.hash(), "code_version": code_version(),
               # the hand gains the verdicts follow, as resolved now (datagen/eval/protocol.py)
               "eval_protocol": recipes[0].eval.protocol,
               "packages": package_versions(), "host": socket.gethostname(), "created_at": created_at}
        with writing(self.path / JOB_JSON):
            atomic_write_text(self.path / JOB_JSON, json.dumps(doc, indent=1, sort_keys=True))

    def recorded_hashes(self) -> dict[str, str]:
        """Config hashes the job's finished work records -> its creation time: the ledger entries'
        ``config_hash`` and the shards' ``datagen.config_hash`` metadata (what job.json can be
        checked, or rebuilt, against)."""
        out: dict[str, str] = {}
        for p in sorted((self.path / LEDGER_DIR).glob("part-*.json")):
            try:
                h = integrity.read_ledger(p).get("config_hash")
            except integrity.ShardError:
                continue
            if isinstance(h, str):
                out.setdefault(h, "")
        for p in sorted((self.path / SHARDS_DIR).glob("part-*.parquet")):
            try:
                meta = pq_schema_metadata(p)
            except Exception:  # noqa: BLE001 - a damaged shard records nothing
                continue
            h = meta.get(b"datagen.config_hash", b"").decode()
            if h:
                out[h] = out.get(h) or meta.get(b"datagen.job_created_at", b"").decode()
        return out

    def _repair_job_json(self, cfg: JobConfig) -> bool:
        """When job.json cannot be read, write it again from ``cfg`` if the job's finished work
        records ``cfg``'s hash and no other (True); otherwise `read_job`'s error. A readable
        job.json: False (nothing to repair)."""
        try:
            self.read_job()
            return False
        except JobError as exc:
            recorded = self.recorded_hashes()
            if set(recorded) != {cfg.hash()}:
                raise exc from None
        self._write_job_json(cfg, recorded[cfg.hash()] or time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
        return True

    @staticmethod
    def _rehash(doc: dict) -> str:
        try:
            return JobConfig.from_dict(doc.get("config")).hash()
        except JobError:
            return ""

    # ------------------------------------------------------------- shards
    def finished(self) -> dict[int, dict]:
        """Ledger entries of finished shards whose files match them (sizes and row counts:
        `audit`), by shard index."""
        return self.audit().finished

    def audit(self, deep: bool = False) -> integrity.Audit:
        """Every ledger entry checked against the files it lists (`datagen.io.integrity.audit`;
        ``deep``: their sha256 too)."""
        return integrity.audit(self.path, deep=deep)

    def record_finished(self, index: int, summary: dict) -> None:
        with writing(self.ledger_path(index), "the ledger entry"):
            self.ledger_path(index).parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.ledger_path(index), json.dumps(summary, indent=1, sort_keys=True))

    def clean_temp(self) -> list[Path]:
        """Remove the temporary files and folders a killed or failed run left (``.<name>.*.tmp``
        in the job's folders, objects being linked in); returns them. Only under the lock: no
        other run of this job writes them now."""
        gone = []
        for d in (self.path, self.path / SHARDS_DIR, self.path / OBSERVATIONS_DIR, self.path / FAILURES_DIR,
                  self.path / LEDGER_DIR, self.path / PROGRESS_DIR, self.objects_dir):
            for p in d.glob(".*.tmp") if d.is_dir() else ():
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
                gone.append(p)
        return gone


def pq_schema_metadata(path: Path) -> dict:
    import pyarrow.parquet as pq

    return pq.read_schema(path).metadata or {}


def shard_size(n_objects: int, workers: int, gpu: bool = False) -> int:
    """Objects per shard for ``n_objects`` on ``workers`` shard slots (``objects_per_shard: auto``).

    ``gpu``: the shards synthesize on GPUs, where a batch costs about the same from 100 to 4000
    poses (latency-bound, `benchmarks/results/synth_cuda.md`): the largest shards that still give
    every slot one, up to ``GPU_AUTO_PER_SHARD``. Otherwise (CPUs):

    Ray hands the shards, in order, to the first free slot. With ``p`` objects per shard there
    are F full shards and maybe a last, shorter one of r objects; the full ones end after
    ceil(F / workers) x p object times, and the short one starts on the first slot to finish its
    floor(F / workers) full shards. The size with the shortest job wins (up to
    ``MAX_AUTO_PER_SHARD``), a 1-object shard's time weighted by its dearer synthesis
    (``SINGLE_OBJECT_COST``: 2 targets per batch against 4, benchmarks/results/synth.md); ties go to
    the size nearest ``PREFERRED_PER_SHARD``, then the larger. The default job (6 objects) on 2
    slots: 3 per shard (2 per shard makes 3 shards and leaves one slot idle for a third of the
    job); on 16 slots: 1; 5000 objects on 2: 2."""
    if n_objects < 1 or workers < 1:
        raise JobError(f"shard_size needs n_objects >= 1 and workers >= 1, got {n_objects}, {workers}")
    if gpu:
        return min(GPU_AUTO_PER_SHARD, -(-n_objects // workers))

    def estimate(p: int) -> float:
        full, rest = divmod(n_objects, p)
        span = -(-full // workers) * p
        if rest:
            span = max(span, (full // workers) * p + rest)
        return span * (SINGLE_OBJECT_COST if p == 1 else 1.0)

    sizes = range(1, min(MAX_AUTO_PER_SHARD, n_objects) + 1)
    return min(sizes, key=lambda p: (round(estimate(p), 9), abs(p - PREFERRED_PER_SHARD), -p))


def shard_slices(n_objects: int, per_shard: int) -> list[tuple[int, int]]:
    """[start, stop) object ranges of the shards."""
    if isinstance(per_shard, bool) or not isinstance(per_shard, int) or per_shard < 1:
        raise JobError(f"shard_slices needs a number of objects per shard >= 1, got {per_shard!r}")
    return [(a, min(a + per_shard, n_objects)) for a in range(0, n_objects, per_shard)]

