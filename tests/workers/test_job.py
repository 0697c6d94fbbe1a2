"""Job directory bookkeeping: config validation and hashing, refusal of a different config, the lock."""

from __future__ import annotations

import json

import pytest

from workers.job import JobConfig, JobDir, JobError, shard_slices

from .conftest import tiny_config


def test_config_validation_names_the_field():
    with pytest.raises(JobError, match="count"):
        JobConfig(count=0)
    with pytest.raises(JobError, match="scales"):
        JobConfig(scales=(0.08, -1.0))
    with pytest.raises(JobError, match="unknown keys"):
        JobConfig.from_dict({"cuont": 3})
    with pytest.raises(JobError, match="coacd_threshold"):  # nested configs are validated up front
        JobConfig(process={"coacd_threshold": 5.0})


def test_hash_is_stable_and_ignores_resources(tmp_path):
    a = tiny_config("procedural")
    b = JobConfig.from_dict(json.loads(json.dumps(a.to_dict())))
    assert a.hash() == b.hash()
    assert JobConfig(**{**a.to_dict(), "cpus_per_shard": 2.0}).hash() == a.hash()
    assert JobConfig(**{**a.to_dict(), "seed": 1}).hash() != a.hash()
    p = tmp_path / "job.yaml"
    p.write_text("count: 4\ntasks: force_closure\nsynth: {iters: 10}\n")
    c = JobConfig.from_yaml(p)
    assert (c.count, c.tasks, c.synth) == (4, ("force_closure",), {"iters": 10})


def test_different_config_is_refused(tmp_path):
    job = JobDir(tmp_path / "job")
    cfg = tiny_config("procedural")
    assert job.init(cfg) is False
    assert job.init(cfg) is True  # same config: resume
    with pytest.raises(JobError, match=r"different job.*'seed'"):
        job.init(JobConfig(**{**cfg.to_dict(), "seed": 7}))


def test_lock_excludes_a_second_driver(tmp_path):
    a, b = JobDir(tmp_path / "job"), JobDir(tmp_path / "job")
    a.lock()
    try:
        with pytest.raises(JobError, match="locked by pid"):
            b.lock()
    finally:
        a.unlock()
    b.lock()  # free again once released
    b.unlock()


def test_shard_slices_cover_every_object_once():
    for n, k in ((1, 1), (7, 3), (9, 3), (5, 10)):
        covered = [i for a, b in shard_slices(n, k) for i in range(a, b)]
        assert covered == list(range(n))
        assert all(b - a <= k for a, b in shard_slices(n, k))
