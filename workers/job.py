"""A job directory: its config, lock, manifest slice, shard layout and ledger of finished shards.

Layout (names are the constants below; paths relative to the job directory)::

    job.json                  the full JobConfig, its hash, code and package versions, created_at
    manifest.jsonl            the manifest slice of this job (objects in shard order)
    shards/part-NNNNN.parquet grasp rows of shard N (`evaluated` schema), written to a temp name
                              and renamed; absent for a finished shard without rows
    failures/part-NNNNN.parquet  failed objects/stages of shard N (`failures` schema)
    failures.parquet          all failures (merged at the end of a run, and by `datagen status`)
    objects/<entry>/          processed objects the rows refer to (hard links into the cache)
    ledger/part-NNNNN.json    written last for a finished shard: its counts and timings
    .lock                     flock held by the running driver
    ray/                      Ray's temp dir when the path is short enough (else /tmp/dg-ray-*)

A job is resumable: re-running the same config skips the shards with a ledger entry and redoes
the others (their outputs are overwritten atomically). A different config is refused.
"""

from __future__ import annotations

import dataclasses
import fcntl
import hashlib
import json
import os
import platform
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from datagen.io.layout import (FAILURES, FAILURES_DIR, JOB_JSON, LEDGER_DIR, LOCK, MANIFEST, OBJECTS_DIR,
                               SHARD_NAME, SHARDS_DIR)

__all__ = ["FAST_PROCESS", "JobConfig", "JobDir", "JobError", "code_version", "package_versions", "shard_slices"]


class JobError(RuntimeError):
    """A job that cannot start or go on (names the job directory and the reason)."""


# A cheap CoACD setting: threshold 0.1 and preprocess resolution 30 are 2-3x faster than the
# objects package's defaults (0.05 / 50) and give coarser but adequate pieces for the hold test
# (NOTES §5). A job's `process` mapping overrides it field by field.
FAST_PROCESS = {"coacd_threshold": 0.1, "coacd_preprocess_resolution": 30, "coacd_mcts_iterations": 60,
                "coacd_mcts_nodes": 10}


@dataclass(frozen=True)
class JobConfig:
    """Everything that determines a job's rows. Hashed: any change is a different job."""

    source: str = "procedural"          #: object source URI (datagen.objects.sources)
    count: int = 6                      #: objects (SCALE)
    scales: tuple = (0.06, 0.08)        #: object scales, metres (of a built manifest; a given
                                        #: manifest's own scales are used as they are)
    test_fraction: float = 0.1          #: manifest split
    manifest: str = ""                  #: existing manifest file (its first `count` objects); "" = build
    hand: str = "shadow"
    tasks: tuple = ("force_closure",)   #: built-in task names or task YAML paths
    grasps_per_object: int = 8          #: per object and scale
    objects_per_shard: int = 2
    seed: int = 0                       #: base seed; shard k synthesizes with seed + k
    grid_resolution: int = 48           #: GraspTarget SDF grid nodes per axis (64: ~25 s/object on
                                        #: one core, 48: ~10 s, 32: ~3 s); built once per object
    object_timeout_s: float = 300.0     #: per-object processing limit (isolated process)
    process: dict = field(default_factory=lambda: dict(FAST_PROCESS))  #: ProcessConfig fields
    synth: dict = field(default_factory=lambda: {"iters": 300})  #: SynthConfig fields
    eval: dict = field(default_factory=dict)  #: EvalConfig fields
    cpus_per_shard: float = 1.0         #: Ray resources of one shard task; also its torch threads
                                        #: (not hashed: keep it fixed within a job for identical floats)
    gpus_per_shard: float = 1.0         #: used only when the cluster has GPUs

    def __post_init__(self):
        def need(ok: bool, what: str):
            if not ok:
                raise JobError(f"JobConfig.{what}")

        object.__setattr__(self, "scales", tuple(float(s) for s in self.scales))
        tasks = (self.tasks,) if isinstance(self.tasks, str) else tuple(str(t) for t in self.tasks)
        object.__setattr__(self, "tasks", tasks)
        need(isinstance(self.count, int) and self.count >= 1, f"count must be an int >= 1, got {self.count!r}")
        need(bool(self.scales) and min(self.scales) > 0, f"scales must be positive metres, got {self.scales}")
        need(bool(self.tasks), "tasks must name at least one task")
        need(self.grasps_per_object >= 1, f"grasps_per_object must be >= 1, got {self.grasps_per_object}")
        need(self.grid_resolution >= 8, f"grid_resolution must be >= 8, got {self.grid_resolution}")
        need(self.objects_per_shard >= 1, f"objects_per_shard must be >= 1, got {self.objects_per_shard}")
        need(self.object_timeout_s > 0, f"object_timeout_s must be > 0 seconds, got {self.object_timeout_s}")
        need(self.cpus_per_shard > 0 and self.gpus_per_shard >= 0, "cpus_per_shard must be > 0, gpus_per_shard >= 0")
        for name in ("process", "synth", "eval"):
            need(isinstance(getattr(self, name), dict), f"{name} must be a mapping of that config's fields")
        self.build_configs()  # validates the nested configs now, not in a worker

    def build_configs(self):
        """(ProcessConfig, SynthConfig, EvalConfig) of this job."""
        from datagen.eval import EvalConfig
        from datagen.objects.config import ProcessConfig
        from datagen.synth import SynthConfig

        return (ProcessConfig.from_dict(self.process), SynthConfig.from_dict(self.synth, where="job synth"),
                EvalConfig.from_dict(self.eval))

    @classmethod
    def from_dict(cls, data: dict | None, where: str = "job config") -> "JobConfig":
        data = dict(data or {})
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise JobError(f"{where}: unknown keys {unknown}; allowed: {sorted(known)}")
        return cls(**data)

    @classmethod
    def from_yaml(cls, path: str | Path) -> "JobConfig":
        try:
            data = yaml.safe_load(Path(path).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise JobError(f"{path}: cannot read the job config: {exc}") from None
        return cls.from_dict(data, where=str(path))

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["scales"], d["tasks"] = list(self.scales), list(self.tasks)
        return d

    def hash(self) -> str:
        """sha256 of the canonical JSON (resources excluded: they do not change rows)."""
        d = self.to_dict()
        d.pop("cpus_per_shard"), d.pop("gpus_per_shard")
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=list).encode()).hexdigest()


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

    def shard_failures_path(self, index: int) -> Path:
        return self.path / FAILURES_DIR / f"{self.shard_name(index)}.parquet"

    def ledger_path(self, index: int) -> Path:
        return self.path / LEDGER_DIR / f"{self.shard_name(index)}.json"

    @property
    def manifest_path(self) -> Path:
        return self.path / MANIFEST

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
        p = self.path / JOB_JSON
        if not p.is_file():
            raise JobError(f"{self.path} is not a job directory (no {JOB_JSON})")
        return json.loads(p.read_text())

    def config(self) -> JobConfig:
        return JobConfig.from_dict(self.read_job()["config"], where=str(self.path / JOB_JSON))

    def init(self, cfg: JobConfig) -> bool:
        """Write job.json, or check that the existing one has the same config hash.
        Returns True when resuming an existing job."""
        p = self.path / JOB_JSON
        if p.is_file():
            old = json.loads(p.read_text())
            if old.get("config_hash") != cfg.hash():
                new = cfg.to_dict()
                diff = sorted(k for k in set(new) | set(old.get("config", {}))
                              if new.get(k) != old.get("config", {}).get(k))
                raise JobError(f"job directory {self.path} holds a different job (config hash "
                               f"{str(old.get('config_hash'))[:12]} != {cfg.hash()[:12]}; fields differing: {diff}); "
                               "re-run with the same settings to resume, or use another --out")
            return True
        for d in (SHARDS_DIR, FAILURES_DIR, OBJECTS_DIR, LEDGER_DIR):
            (self.path / d).mkdir(parents=True, exist_ok=True)
        doc = {"config": cfg.to_dict(), "config_hash": cfg.hash(), "code_version": code_version(),
               "packages": package_versions(), "host": socket.gethostname(),
               "created_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        atomic_write_text(p, json.dumps(doc, indent=1, sort_keys=True))
        return False

    # ------------------------------------------------------------- shards
    def finished(self) -> dict[int, dict]:
        """Ledger entries of finished shards, by shard index."""
        out = {}
        for p in sorted((self.path / LEDGER_DIR).glob("part-*.json")):
            out[int(p.stem.split("-")[1])] = json.loads(p.read_text())
        return out

    def record_finished(self, index: int, summary: dict) -> None:
        atomic_write_text(self.ledger_path(index), json.dumps(summary, indent=1, sort_keys=True))


def shard_slices(n_objects: int, per_shard: int) -> list[tuple[int, int]]:
    """[start, stop) object ranges of the shards."""
    return [(a, min(a + per_shard, n_objects)) for a in range(0, n_objects, per_shard)]


def atomic_write_text(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
