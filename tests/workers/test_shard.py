"""The per-shard pipeline without Ray: rows, failures, self-contained object paths, atomic
writes, the per-object time limit, determinism."""

from __future__ import annotations

import json

import os
from pathlib import Path

import pyarrow.parquet as pq
import pytest

import workers.shard as shard_mod
from schemas import arrow_schema, check_version
from workers.job import JobConfig, JobDir, shard_slices
from workers.finished import merge_failures
from workers.setup import prepare_manifest
from workers.shard import run_shard

from .conftest import comparable_rows, tiny_config


def run_all(job_dir: Path, cfg: JobConfig, cache: str, only=None) -> JobDir:
    job = JobDir(job_dir)
    job.init(cfg)
    entries = prepare_manifest(job, cfg)
    doc = job.read_job()
    prov = {"code_version": doc["code_version"], "packages": doc["packages"], "created_at": doc["created_at"],
            "cache": cache}
    for i, (a, b) in enumerate(shard_slices(len(entries), cfg.objects_per_shard)):
        if only is None or i in only:
            ents = [{**e.__dict__, "scales": list(e.scales)} for e in entries[a:b]]
            run_shard(str(job.path), i, ents, cfg.to_dict(), prov)
    merge_failures(job)
    return job


@pytest.fixture(scope="module")
def done_job(tmp_path_factory, mesh_source, cache_dir):
    return run_all(tmp_path_factory.mktemp("shardjob") / "job", tiny_config(mesh_source), cache_dir)


def test_rows_failures_and_provenance(done_job):
    job = done_job
    assert sorted(job.finished()) == [0, 1, 2]
    rows = comparable_rows(job.path)
    assert len(rows) == 2 * 2  # two good objects x one scale x two grasps
    assert {r["object_id"] for r in rows} == {"a_box.obj", "b_ball.obj"}
    fails = pq.read_table(job.failures_path).to_pylist()
    assert [(f["object_id"], f["stage"]) for f in fails] == [("c_bad.obj", "process")]
    assert fails[0]["reason"] and "c_bad" in fails[0]["message"]
    t = pq.read_table(job.shard_path(0))
    check_version(t.schema, "evaluated")
    assert t.schema.remove_metadata().equals(arrow_schema("evaluated", nq=t.schema.field("grasp_qpos").type.list_size)
                                             .remove_metadata())
    meta = {k.decode(): v.decode() for k, v in t.schema.metadata.items()}
    for key in ("datagen.joint_names", "datagen.code_version", "datagen.config_hash", "datagen.packages",
                "datagen.host", "datagen.written_at"):
        assert meta.get(key), key
    assert meta["datagen.config_hash"] == job.read_job()["config_hash"]


def test_rows_point_into_the_job_dir(done_job):
    for r in comparable_rows(done_job.path):
        assert not os.path.isabs(r["object_path"])
        assert (done_job.path / r["object_path"] / "meta.json").is_file()
        assert r["success"] in (True, False) and r["reason"]


def test_same_config_same_rows(tmp_path, mesh_source, cache_dir, done_job):
    again = run_all(tmp_path / "again", tiny_config(mesh_source), cache_dir, only={0, 1})
    ref = [r for r in comparable_rows(done_job.path) if r["object_id"] in ("a_box.obj", "b_ball.obj")]
    assert comparable_rows(again.path) == ref


def test_failing_shard_write_leaves_no_partial_file(tmp_path, mesh_source, cache_dir, monkeypatch):
    from workers.job import JobIOError

    real = shard_mod.pq.write_table
    cfg = tiny_config(mesh_source)
    run_all(tmp_path / "job", cfg, cache_dir, only=set())  # the job and its manifest, no shard yet

    def broken(table, where, **kw):
        real(table.slice(0, 1), where, **kw)  # something reaches the disk, then the write fails
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(shard_mod.pq, "write_table", broken)
    with pytest.raises(JobIOError, match=r"cannot write the Parquet file .*shards/part-00000.parquet: No space left "
                                         r"on device \(free space on the file system holding .*shards"):
        run_all(tmp_path / "job", cfg, cache_dir, only={0})
    job = JobDir(tmp_path / "job")
    assert not job.shard_path(0).exists()
    assert list((job.path / "shards").iterdir()) == []  # no temp file left either
    assert job.finished() == {}  # not in the ledger: a rerun redoes it


def test_object_timeout_is_a_recorded_failure(tmp_path, mesh_source):
    cfg = tiny_config(mesh_source, object_timeout_s=0.05, count=1)
    job = run_all(tmp_path / "job", cfg, str(tmp_path / "fresh_cache"))
    fails = pq.read_table(job.failures_path).to_pylist()
    assert [(f["object_id"], f["stage"], f["reason"]) for f in fails] == [("a_box.obj", "process", "timeout")]
    assert not job.shard_path(0).exists()  # a shard without rows has no file
    assert job.finished()[0]["failures"] == 1


def test_status_and_report(done_job, capsys):
    from datagen.cli import main
    from workers.report import write_report
    from workers.status import job_status

    rows = comparable_rows(done_job.path)
    s = job_status(done_job.path)
    assert (s["shards_done"], s["shards_total"], s["complete"]) == (3, 3, True)
    assert (s["grasps"], s["success"]) == (len(rows), sum(r["success"] for r in rows))
    (reason,) = pq.read_table(done_job.failures_path)["reason"].to_pylist()
    assert s["failures"] == {f"process:{reason}": 1}
    assert main(["status", str(done_job.path)]) == 0
    assert f"grasps   {len(rows)}" in capsys.readouterr().out
    card = write_report(done_job.path, renders=1).read_text()
    assert "# Dataset card" in card and f"| process | {reason} | 1 |" in card
    # the hand gains the verdicts follow: in job.json, each shard's eval config and the card
    assert json.loads((done_job.path / "job.json").read_text())["eval_protocol"] == "dexgraspbench"
    shard = next(done_job.shard_path(i) for i in range(3) if done_job.shard_path(i).is_file())
    meta = pq.read_schema(shard).metadata
    assert json.loads(meta[b"datagen.eval_config"])["protocol"] == "dexgraspbench"
    assert "- hand gains: protocol `dexgraspbench`" in card
    pics = sorted((done_job.path / "renders").glob("*.png")) if (done_job.path / "renders").is_dir() else []
    if pics:  # an offscreen GL context was available
        assert f"![renders/{pics[0].name}]" in card
    else:
        assert "No grasp pictures" in card


def test_native_scale_rows_and_a_mesh_not_in_metres(tmp_path, cache_dir):
    import numpy as np
    import trimesh

    root = tmp_path / "meshes"
    root.mkdir()
    trimesh.creation.box((0.1, 0.06, 0.04)).export(root / "a_box_m.obj")  # metres
    trimesh.creation.box((100.0, 60.0, 40.0)).export(root / "b_box_mm.obj")  # millimetres
    cfg = tiny_config(f"dir:{root}", count=2, scales=("native",))
    job = run_all(tmp_path / "job", cfg, cache_dir)
    rows = comparable_rows(job.path)
    assert {r["object_id"] for r in rows} == {"a_box_m.obj"}
    half_diagonal = np.sqrt(0.1 ** 2 + 0.06 ** 2 + 0.04 ** 2) / 2
    assert all(abs(r["object_scale_m"] - half_diagonal) < 1e-6 for r in rows)
    fails = pq.read_table(job.failures_path).to_pylist()
    assert [(f["object_id"], f["reason"]) for f in fails] == [("b_box_mm.obj", "native_size_out_of_range")]
    assert "millimetres" in fails[0]["message"]


def test_a_shard_runs_where_ray_is_not_installed(tmp_path, mesh_source, cache_dir, monkeypatch):
    """`benchmarks/cuda_shards.py` runs shards in-process on machines without Ray (a GPU box that
    cannot install it): the shard's idle-core question must not import it (it did, and failed)."""
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    with pytest.raises(ImportError):
        import ray  # noqa: F401
    assert shard_mod._idle_cores() is None
    job = run_all(tmp_path / "job", tiny_config(mesh_source), cache_dir, only={0})
    rows = pq.read_table(job.shard_path(0))
    assert rows.num_rows > 0
