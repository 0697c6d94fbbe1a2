"""Every row names its own object and every failure its cause: identical files under two names,
files that vanish or change after the manifest, settings refused before any work, a timeout that
is an execution setting, --retry-failed, shard metadata and the read-side schema check."""

from __future__ import annotations

import collections
import json
import shutil
import tempfile
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import trimesh

from datagen import cli
from datagen.io import ShardError, integrity
from schemas import SchemaError, check_version, columns
from workers.job import JobConfig, JobDir
from workers.cluster import _ray_temp_dir
from workers.setup import prepare_manifest

from .conftest import TINY_EVAL, comparable_rows, tiny_config
from .test_shard import run_all


def _box(path: Path, extents=(1.0, 0.7, 0.5)) -> bytes:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents).export(path)
    return path.read_bytes()


def test_identical_files_keep_their_own_ids_and_rows(tmp_path, cache_dir):
    root = tmp_path / "meshes"
    data = _box(root / "twin_a.obj")
    (root / "twin_b.obj").write_bytes(data)
    trimesh.creation.icosphere(subdivisions=2).export(root / "c_ball.obj")
    cfg = tiny_config(f"dir:{root}", count=3, objects_per_shard=3)  # both twins in one batch
    job = run_all(tmp_path / "job", cfg, cache_dir)
    rows = comparable_rows(job.path)
    assert collections.Counter(r["object_id"] for r in rows) == {"twin_a.obj": 2, "twin_b.obj": 2, "c_ball.obj": 2}
    assert len({r["grasp_id"] for r in rows}) == len(rows)
    assert pq.read_table(job.failures_path).num_rows == 0


def test_vanished_or_changed_file_is_a_failure_without_rows(tmp_path, cache_dir):
    root = tmp_path / "meshes"
    _box(root / "gone.obj")
    _box(root / "changed.obj", (0.9, 0.9, 0.4))
    cfg = tiny_config(f"dir:{root}", count=2, objects_per_shard=2)
    job = JobDir(tmp_path / "job")
    job.init(cfg)
    entries = prepare_manifest(job, cfg)
    from datagen.objects.isolate import process_isolated

    pcfg = cfg.recipes()[0].process
    for e in entries:  # both are in the cache, under the manifest's hashes, as after an earlier job
        assert process_isolated(e, pcfg, cache_dir, 120).ok
    (root / "gone.obj").unlink()
    _box(root / "changed.obj", (0.3, 0.9, 0.4))
    run_all(job.path, cfg, cache_dir)
    assert not job.shard_path(0).exists()  # no rows
    got = {(f["object_id"], f["stage"], f["reason"]) for f in pq.read_table(job.failures_path).to_pylist()}
    assert got == {("gone.obj", "process", "missing_file"), ("changed.obj", "process", "sha256_mismatch")}


def test_symlink_escape_after_the_manifest_keeps_its_cause(tmp_path, cache_dir):
    root = tmp_path / "meshes"
    data = _box(root / "a.obj")
    cfg = tiny_config(f"dir:{root}", count=1)
    job = JobDir(tmp_path / "job")
    job.init(cfg)
    prepare_manifest(job, cfg)
    (tmp_path / "outside.obj").write_bytes(data)
    (root / "a.obj").unlink()
    (root / "a.obj").symlink_to(tmp_path / "outside.obj")
    run_all(job.path, cfg, cache_dir)  # the job's own manifest still loads
    (f,) = pq.read_table(job.failures_path).to_pylist()
    assert (f["stage"], f["reason"]) == ("process", "path_escapes_root"), f


@pytest.mark.parametrize("flag,value,named,valid", [("--hand", "nohand", "unknown hand 'nohand'", "shadow"),
                                                    ("--tasks", "force_closure,nope", "unknown task 'nope'",
                                                     "turn_knob2"),
                                                    ("--seed", "-1", "seed must be", "[0, 2**62)")])
def test_bad_settings_are_refused_before_any_work(flag, value, named, valid, tmp_path, mesh_source, capsys):
    import ray

    out = tmp_path / "job"
    code = cli.main(["run", "--out", str(out), "--source", mesh_source, flag, value, "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert named in err and valid in err, err
    assert not out.exists() and not ray.is_initialized()  # no half job, no cluster, no object processed


def test_timeout_is_not_part_of_the_job_identity(tmp_path):
    cfg = tiny_config("procedural")
    longer = JobConfig(**{**cfg.to_dict(), "object_timeout_s": 900.0})
    assert longer.hash() == cfg.hash()
    job = JobDir(tmp_path / "job")
    job.init(cfg)
    assert job.init(longer) is True  # resumes, not refused
    # a job made when the timeout was hashed still resumes
    doc = json.loads((job.path / "job.json").read_text())
    doc["config_hash"] = "0" * 64
    (job.path / "job.json").write_text(json.dumps(doc))
    assert job.init(longer) is True
    assert json.loads((job.path / "job.json").read_text())["config_hash"] == cfg.hash()


def test_shard_metadata_progress_and_every_shard_schema(tmp_path, mesh_source, cache_dir):
    from datagen.eval import EvalConfig
    from datagen.eval.table import evaluate_table
    from datagen.io import open_dataset
    from workers.cli import closing_summary
    from workers.status import format_status, job_status

    cfg = tiny_config(mesh_source, count=2, seed=5)
    job = run_all(tmp_path / "job", cfg, cache_dir)
    for i in (0, 1):
        meta = pq.read_schema(job.shard_path(i)).metadata
        assert meta[b"datagen.seed"] == str(5 + i).encode()
        assert json.loads(meta[b"datagen.synth_config"])["seed"] == 5 + i
        prog = json.loads(job.progress_path(i).read_text())
        assert prog["done"] == prog["total"] > 0
    assert open_dataset(job.path).count_rows() == 4
    # a second shard of another schema version is refused, not read
    t = pq.read_table(job.shard_path(1))
    meta = dict(t.schema.metadata)
    meta[b"datagen.schema_version"] = b"99"
    pq.write_table(t.replace_schema_metadata(meta), job.shard_path(1))
    with pytest.raises(ShardError, match=r"part-00001.parquet: (truncated|changed size): .* bytes, the ledger "):
        open_dataset(job.path)  # a file the ledger does not vouch for
    entry = json.loads(job.ledger_path(1).read_text())
    entry["files"]["shards/part-00001.parquet"] = integrity.file_record(job.shard_path(1))
    job.record_finished(1, entry)  # as if another code version had written it
    with pytest.raises(SchemaError, match="part-00001"):
        open_dataset(job.path)
    # `datagen eval` of a grasps table writes an `evaluated` table
    t = pq.read_table(job.shard_path(0))
    grasps = t.select([c["name"] for c in columns("grasps")]).slice(0, 1)
    grasps = grasps.replace_schema_metadata({b"datagen.schema": b"grasps", b"datagen.schema_version": b"1"})
    out = evaluate_table(grasps, EvalConfig.from_dict(TINY_EVAL), base=job.path)
    check_version(out.schema, "evaluated")
    # status names its stages; the closing summary says where the data is and what to run next
    s = job_status(job.path)
    assert "target = the synthesis target" in format_status(s)
    text = closing_summary(s)
    assert "part-00000.parquet" in text and f"datagen report {job.path}" in text and "read_job(" in text


def test_hand_cache_follows_datagen_cache(tmp_path, monkeypatch):
    from datagen.hands.mjcf import cache_dir

    monkeypatch.setenv("DATAGEN_CACHE", str(tmp_path / "c"))
    monkeypatch.delenv("DATAGEN_CACHE_DIR", raising=False)
    assert cache_dir() == tmp_path / "c" / "hands"


def test_ray_temp_dir_is_private(tmp_path):
    short = Path(tempfile.mkdtemp(prefix="dg", dir="/tmp"))
    try:
        for job in (JobDir(short / "j"), JobDir(tmp_path / ("long" * 12))):
            path, private = _ray_temp_dir(job)
            assert Path(path).stat().st_mode & 0o777 == 0o700
            if private:  # the /tmp/dg-ray-* one of the long path
                shutil.rmtree(path)
    finally:
        shutil.rmtree(short)


@pytest.mark.ray
def test_retry_failed_redoes_a_timeout_with_a_longer_limit(tmp_path, cache_dir):
    from workers.run import run_job

    root = tmp_path / "meshes"
    _box(root / "slow.obj", (1.0, 0.8, 0.3))  # bytes no other test has cached
    fresh = str(tmp_path / "cache")
    cfg = tiny_config(f"dir:{root}", count=1, object_timeout_s=0.01)
    short = Path(tempfile.mkdtemp(prefix="dg", dir="/tmp"))  # Ray's temp dir inside the job
    try:
        out = short / "j"
        run_all(out, cfg, fresh)
        quiet = dict(num_cpus=1, cache=fresh, progress=False, log=lambda *a: None)
        longer = JobConfig(**{**cfg.to_dict(), "object_timeout_s": 300.0})
        s = run_job(longer, out, **quiet)  # accepted; nothing to run without --retry-failed
        assert s["failures"] == {"process:timeout": 1} and s["retryable"] == 1
        s = run_job(longer, out, retry_failed=True, **quiet)
        assert s["complete"] and s["failures"] == {} and s["grasps"] == 2 and s["retryable"] == 0
        assert (out / "ray").stat().st_mode & 0o777 == 0o700
    finally:
        shutil.rmtree(short, ignore_errors=True)


def test_an_unpicklable_shard_error_keeps_its_cause(tmp_path, mesh_source, monkeypatch):
    import pickle

    import workers.shard as shard_mod

    class Unpicklable(Exception):
        def __init__(self, thing, reason):
            super().__init__(f"{thing}: {reason}")

    def broken(*a, **k):
        raise Unpicklable("hand 'x'", "asset missing on this node")

    monkeypatch.setattr(shard_mod, "_run_shard", broken)
    with pytest.raises(RuntimeError) as info:
        shard_mod.run_shard(str(tmp_path), 3, [], {}, {})
    assert str(info.value) == "shard 3: Unpicklable: hand 'x': asset missing on this node"
    pickle.loads(pickle.dumps(info.value))  # Ray can ship it


def test_a_ray_task_error_becomes_one_clean_line():
    from workers.cluster import error_line

    class FakeRayTaskError(Exception):  # what ray.get raises: a traceback with colours, and the cause
        def __init__(self, cause):
            super().__init__("\x1b[36mray::run_shard()\x1b[39m (pid=1, ip=10.0.0.1)\n  File x, line 3\n"
                             + f"{type(cause).__name__}: {cause}")
            self.cause = cause

    assert error_line(FakeRayTaskError(ValueError("unknown task 'nope'"))) == "ValueError: unknown task 'nope'"
    assert error_line(RuntimeError("\x1b[31mboom\x1b[0m\n")) == "RuntimeError: boom"


def test_a_shard_uses_the_jobs_cache_for_its_hand_and_restores_the_environment(tmp_path, monkeypatch):
    import os

    import workers.shard as shard_mod

    seen = []
    monkeypatch.setenv("DATAGEN_CACHE", str(tmp_path / "mine"))
    monkeypatch.setattr(shard_mod, "_run_shard", lambda *a: seen.append(os.environ["DATAGEN_CACHE"]) or {})
    shard_mod.run_shard(str(tmp_path), 0, [], {}, {"cache": str(tmp_path / "job_cache")})
    assert seen == [str(tmp_path / "job_cache")]
    assert os.environ["DATAGEN_CACHE"] == str(tmp_path / "mine")
