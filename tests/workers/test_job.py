"""Job directory bookkeeping: config validation and hashing, refusal of a different config, the lock."""

from __future__ import annotations

import json

import pytest

import heapq

from workers.job import AUTO, SINGLE_OBJECT_COST, JobConfig, JobDir, JobError, shard_size, shard_slices
from workers.cluster import worker_slots
from workers.run import _resolve_layout

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


def test_a_job_made_before_a_config_field_existed_is_refused_naming_it(tmp_path, monkeypatch):
    # a job.json of a version without `observations` (issue 46) whose recipes also differ (its
    # library defaults changed since: its config no longer hashes to this one): refused, naming the
    # field, the version that made it and what to do, not "re-run with the same settings"
    monkeypatch.setattr(JobDir, "_rehash", staticmethod(lambda doc: "changed recipes"))
    job = JobDir(tmp_path / "job")
    cfg = tiny_config("procedural")
    job.init(cfg)
    doc = json.loads((job.path / "job.json").read_text())
    del doc["config"]["observations"]
    doc["config_hash"], doc["code_version"] = "0" * 64, "0.1.0+gabc"
    (job.path / "job.json").write_text(json.dumps(doc))
    with pytest.raises(JobError, match=r"made by datagen 0\.1\.0\+gabc, before observations existed.*another --out"):
        job.init(cfg)


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


def _list_schedule_makespan(n: int, per_shard: int, workers: int) -> float:
    """Makespan of the shards handed out in order to the first free worker (as Ray does), each
    lasting its objects x the per-object cost (a 1-object shard's dearer synthesis included)."""
    free = [0.0] * workers
    for a, b in shard_slices(n, per_shard):
        t = heapq.heappop(free)
        heapq.heappush(free, t + (b - a) * (SINGLE_OBJECT_COST if per_shard == 1 else 1.0))
    return max(free)


def test_shard_size_fills_the_workers():
    # hand-worked: 6 objects on 2 slots -> 2 shards of 3 (2 per shard leaves a slot idle for the
    # third shard); on 16 slots one per shard; a long job keeps the preferred 2
    assert [shard_size(6, 2), shard_size(6, 16), shard_size(5000, 2), shard_size(1, 8), shard_size(3, 2)] == [3, 1, 2, 1, 2]
    for n in range(1, 41):
        for w in (1, 2, 3, 4, 8, 16):
            p = shard_size(n, w)
            best = min(_list_schedule_makespan(n, k, w) for k in range(1, min(4, n) + 1))
            assert _list_schedule_makespan(n, p, w) == pytest.approx(best), (n, w, p)
    with pytest.raises(JobError, match="workers >= 1"):
        shard_size(6, 0)
    # on GPUs: the largest shards (one synthesis batch each, up to 16 objects) that keep every
    # slot busy: one GPU takes 16 objects at a time, 8 GPUs share 40 objects 5 each
    assert [shard_size(6, 1, gpu=True), shard_size(100, 1, gpu=True), shard_size(40, 8, gpu=True),
            shard_size(3, 8, gpu=True)] == [6, 16, 5, 1]


def test_auto_layout_is_chosen_once_and_kept_on_resume(tmp_path):
    cfg = tiny_config("procedural", count=6, objects_per_shard=AUTO)
    assert worker_slots(cfg, None, 2) == (2, False, False)
    assert worker_slots(JobConfig(**{**cfg.to_dict(), "cpus_per_shard": 2.0}), None, 8) == (4, False, False)
    # a local machine with GPUs (faked: no GPU needed): one shard per GPU, however many cores
    with pytest.MonkeyPatch.context() as mp:
        import torch

        mp.setattr(torch.cuda, "is_available", lambda: True)
        mp.setattr(torch.cuda, "device_count", lambda: 2)
        assert worker_slots(cfg, None, 16) == (2, False, True)
        assert worker_slots(JobConfig(**{**cfg.to_dict(), "gpus_per_shard": 0.0}), None, 16) == (16, False, False)
    job = JobDir(tmp_path / "job")
    with pytest.raises(JobError, match="'auto' must be resolved"):
        job.init(cfg)
    resolved, connected = _resolve_layout(cfg, job, None, 2)
    assert (resolved.objects_per_shard, connected) == (3, False)
    assert job.init(resolved) is False
    assert json.loads((job.path / "job.json").read_text())["config"]["objects_per_shard"] == 3
    # resumed on a machine with more cores: the recorded layout, not a new one
    again, _ = _resolve_layout(cfg, job, None, 16)
    assert again.objects_per_shard == 3 and job.init(again) is True
    with pytest.raises(JobError, match=r"different job.*'objects_per_shard'"):
        job.init(JobConfig(**{**cfg.to_dict(), "objects_per_shard": 2}))
    with pytest.raises(JobError, match="objects_per_shard"):
        JobConfig(objects_per_shard="many")


def test_grasp_types_are_a_recipe_layer_of_the_job(tmp_path):
    """``grasp_types`` in a job config (or ``--grasp-type``) reaches every task's recipe and the
    hash; an unknown type is refused naming it."""
    import argparse

    from datagen.tasks import GraspMix
    from workers.cli import _config, register_run

    base = tiny_config("procedural")
    power = JobConfig(**{**base.to_dict(), "grasp_types": "power"})
    assert power.recipes()[0].grasp_types == GraspMix.single("power")
    assert power.hash() != base.hash()
    with pytest.raises(JobError, match="unknown grasp type 'hook'"):
        JobConfig(**{**base.to_dict(), "grasp_types": "hook"})
    ap = argparse.ArgumentParser()
    register_run(ap.add_subparsers(dest="cmd"))
    args = ap.parse_args(["run", "--out", str(tmp_path / "j"), "--grasp-type", "power"])
    assert _config(args).recipes()[0].grasp_types == GraspMix.single("power")


def test_a_worker_that_resolves_the_settings_differently_stops_its_shard(tmp_path):
    """A shard worker's code resolves the job's recipes again; if they are not job.json's (code
    edited mid-job, a node on another version), the shard stops naming what differs instead of
    writing rows the job does not describe."""
    from workers.shard import same_recipes

    job = JobDir(tmp_path / "job")
    cfg = tiny_config("procedural")
    job.init(cfg)
    assert same_recipes(job, cfg.recipes()) == cfg.recipes()
    other = JobConfig(**{**cfg.to_dict(), "synth": {**cfg.synth, "iters": 11}})  # as another code's resolver
    with pytest.raises(JobError, match=r"resolves the job's settings differently.*0\.synth"):
        same_recipes(job, other.recipes())
