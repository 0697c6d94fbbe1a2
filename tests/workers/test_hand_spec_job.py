"""A job with a hand given as a spec file (issue 43): the job pins the hand, its rows name it,
and every reader loads it from the job alone after the job is moved and the spec deleted; a
changed asset is refused naming the hand; a broken hand is refused before the job exists."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from datagen.cli import main as cli
from datagen.hands import load_hand, load_spec, make_spec
from datagen.io import read_job
from tests.hands.test_spec import write_toy_urdf
from workers.job import JobDir, JobError, shard_slices
from workers.finished import merge_failures
from workers.setup import pin_job_hand, prepare_manifest
from workers.shard import run_shard

from .conftest import tiny_config


def run_job_in_process(out: Path, cfg, cache: str) -> JobDir:
    """What `workers.run.run_job` does before and around Ray, with the shards run here."""
    hand = cfg.check_runnable()
    job = JobDir(out)
    job.init(cfg)
    pin_job_hand(job, hand.spec)
    entries = prepare_manifest(job, cfg)
    doc = job.read_job()
    prov = {"code_version": doc["code_version"], "packages": doc["packages"], "created_at": doc["created_at"],
            "cache": cache, "hand": hand.name}
    for i, (a, b) in enumerate(shard_slices(len(entries), cfg.objects_per_shard)):
        run_shard(str(job.path), i, [{**e.__dict__, "scales": list(e.scales)} for e in entries[a:b]],
                  cfg.to_dict(), prov)
    merge_failures(job)
    return job


def user_hand(root: Path) -> Path:
    """A user's two-finger URDF hand in ``root`` and the spec `make_spec` proposes for it (fingers
    detected) in a folder that does not exist yet."""
    urdf = write_toy_urdf(root)
    spec = root / "specs" / "toy.yaml"
    assert make_spec.main([str(urdf), "--name", "toy", "--root-body", "palm", "--out", str(spec)]) == 0
    return spec


@pytest.fixture(scope="module")
def toy_spec(tmp_path_factory) -> Path:
    return user_hand(tmp_path_factory.mktemp("userhand"))


@pytest.fixture(scope="module")
def moved_job(tmp_path_factory, mesh_source, cache_dir):
    """The tiny job run with ``--hand toy.yaml``, then moved elsewhere with the spec deleted."""
    tmp = tmp_path_factory.mktemp("specjob")
    toy_spec = user_hand(tmp)
    cfg = tiny_config(mesh_source, hand=str(toy_spec), count=1)
    job = run_job_in_process(tmp / "job", cfg, cache_dir)
    rows = pq.read_table(job.shard_path(0)).to_pylist()
    moved = tmp / "elsewhere" / "job"
    moved.parent.mkdir()
    shutil.move(str(job.path), moved)
    shutil.rmtree(toy_spec.parent)  # the job alone must be enough
    return moved, rows


def _clean(v):
    return "nan" if isinstance(v, float) and math.isnan(v) else v


def test_job_pins_the_hand_and_rows_name_it(moved_job):
    job, rows = moved_job
    assert rows and {r["hand"] for r in rows} == {"toy"}
    pinned = load_spec(job / "hands" / "toy.yaml")
    assert pinned.name == "toy" and len(pinned.mjcf.sha256) == 64
    assert Path(pinned.mjcf.path).is_absolute() and Path(pinned.mjcf.path).name == "toy.urdf"
    assert read_job(job).num_rows == len(rows)


def test_eval_of_the_moved_job_gives_the_shard_verdicts(moved_job, tmp_path, capsys):
    import json

    import yaml

    job, rows = moved_job
    out = tmp_path / "evaluated" / "ev.parquet"
    config = tmp_path / "eval.yaml"  # the job's own test (the tiny one), as its shards ran it
    config.write_text(yaml.safe_dump(json.loads((job / "job.json").read_text())["config"]["eval"]))
    assert cli(["eval", str(job), "--out", str(out), "--config", str(config)]) == 0, capsys.readouterr().err
    again = pq.read_table(out).to_pylist()
    cols = ("grasp_id", "success", "reason", "penetration_m", "dir_success")
    assert [[_clean(r[c]) for c in cols] for r in again] == [[_clean(r[c]) for c in cols] for r in rows]
    assert (out.parent / "hands" / "toy.yaml").is_file()  # the output table takes its hand along


def test_view_and_report_load_the_hand_from_the_job(moved_job):
    from datagen.view.posing import SceneCache

    job, _ = moved_job
    assert SceneCache(base=job).hand("toy").num_joints == 4
    assert load_hand("toy", base=job).joint_names == ["a_j0", "a_j1", "b_j0", "b_j1"]


def test_a_changed_asset_is_refused_naming_the_hand(moved_job, tmp_path, capsys):
    job, _ = moved_job
    urdf = Path(load_spec(job / "hands" / "toy.yaml").mjcf.path)
    original = urdf.read_bytes()
    try:
        urdf.write_bytes(original.replace(b'upper="1.5"', b'upper="1.4"', 1))
        assert cli(["eval", str(job), "--out", str(tmp_path / "ev.parquet")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "hand 'toy'" in err[0] and str(urdf) in err[0] and "differ" in err[0]
        assert not (tmp_path / "ev.parquet").exists()
    finally:
        urdf.write_bytes(original)


def test_a_copy_of_a_builtin_spec_under_another_name(tmp_path):
    import yaml

    from datagen.hands import builtin_spec_path
    from datagen.hands.load import builtin_of

    data = yaml.safe_load(builtin_spec_path("shadow").read_text())
    data["name"] = "my_shadow"
    path = tmp_path / "my_shadow.yaml"
    path.write_text(yaml.safe_dump(data))
    pinned = load_spec(make_pin(path, tmp_path / "table"))
    assert pinned.mjcf.package == "gymnasium_robotics" and pinned.name == "my_shadow"
    hand = load_hand("my_shadow", base=tmp_path / "table")
    assert hand.num_joints == load_hand("shadow").num_joints and builtin_of(hand.spec) == "shadow"
    with pytest.raises(ValueError, match="not a built-in hand name"):
        load_hand("my_shadow", base=tmp_path)  # nothing pinned there


def make_pin(spec_path: Path, base: Path) -> Path:
    from datagen.hands import pin_hand

    return pin_hand(load_spec(spec_path), base)


def test_a_pinned_name_is_not_taken_by_another_spec(toy_spec, tmp_path):
    import yaml

    from datagen.hands import HandSpecError

    pin = make_pin(toy_spec, tmp_path)
    assert make_pin(toy_spec, tmp_path) == pin  # the same spec again: kept
    data = yaml.safe_load(toy_spec.read_text())
    data["sphere_margin_m"] = 0.001
    other = tmp_path / "toy2.yaml"
    other.write_text(yaml.safe_dump({**data, "mjcf": {"path": str(toy_spec.parent.parent / "toy.urdf")}}))
    with pytest.raises(HandSpecError, match="holds another hand named 'toy'") as err:
        make_pin(other, tmp_path)
    assert str(pin) in str(err.value)


def test_a_broken_hand_is_refused_before_the_job_exists(tmp_path, mesh_source, toy_spec, capsys):
    urdf_dir = tmp_path / "broken"
    urdf_dir.mkdir()
    urdf = write_toy_urdf(urdf_dir, mesh_name="meshes/nowhere.stl", make_mesh=False)
    spec = load_spec(toy_spec)
    import dataclasses

    from datagen.hands.spec import AssetRef, dump_spec

    bad = urdf_dir / "toy.yaml"
    dump_spec(dataclasses.replace(spec, mjcf=AssetRef(path=str(urdf))), bad)
    with pytest.raises(JobError, match="nowhere.stl"):
        tiny_config(mesh_source, hand=str(bad)).check_runnable()
    out = tmp_path / "job"
    assert cli(["run", "--hand", str(bad), "--source", mesh_source, "--objects", "1", "--out", str(out),
                "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere.stl" in err[0] and str(bad) in err[0]
    assert not out.exists()
