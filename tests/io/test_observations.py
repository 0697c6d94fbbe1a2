"""Object observations in a job: written beside the shards, declared by their schema, vouched for
by the ledger (`datagen verify`), read back by plain pyarrow and joined to the grasps on object id
and scale, and paired with the grasps by the torch Dataset."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch

from datagen import cli
from datagen.io import GraspDataset, ObservationGraspDataset, ShardError, read_job, read_observations
from schemas import arrow_schema

from .conftest import OBSERVATIONS

pytestmark = pytest.mark.slow  # the session's tiny job


@pytest.fixture(scope="module")
def raw(job_dir):
    """Reference: the observation files read by plain pyarrow, no project code."""
    return pq.read_table(job_dir / "observations").to_pylist()


def test_one_row_per_object_and_scale_of_the_declared_schema(job_dir, raw):
    assert sorted((r["object_id"], round(r["object_scale_m"], 6)) for r in raw) == [
        ("a_box.obj", 0.06), ("a_box.obj", 0.08), ("b_ball.obj", 0.06), ("b_ball.obj", 0.08)]
    for p in sorted((job_dir / "observations").glob("part-*.parquet")):
        schema = pq.read_schema(p)
        assert schema.equals(arrow_schema("observations"), check_metadata=False)
        meta = {k.decode(): v.decode() for k, v in schema.metadata.items()}
        assert meta["datagen.schema"] == "observations"
        assert json.loads(meta["datagen.observation_config"])["views"] == 2
    for r in raw:
        assert len(r["surface_points_m"]) == len(r["surface_normals"]) == OBSERVATIONS["points"]
        assert len(r["camera_poses"]) == len(r["view_points_m"]) == 2
        assert all(0 < len(v) <= OBSERVATIONS["view_points"] for v in r["view_points_m"])
        assert r["depth_renderer"] in ("mujoco", "raycast")
        lo, hi = np.array(r["bbox_min_m"]), np.array(r["bbox_max_m"])
        pts = np.array(r["surface_points_m"])
        assert np.all(pts >= lo - 1e-6) and np.all(pts <= hi + 1e-6)
        # the rows' object frame: the bounding box is centred, its longest side the scale's
        np.testing.assert_allclose((lo + hi) / 2, 0, atol=1e-6)


def test_the_ledger_lists_the_observation_files(job_dir):
    for p in sorted((job_dir / "observations").glob("part-*.parquet")):
        entry = json.loads((job_dir / "ledger" / p.name.replace(".parquet", ".json")).read_text())
        rec = entry["files"][f"observations/{p.name}"]
        assert rec["bytes"] == p.stat().st_size and rec["rows"] == entry["observations"] == 2


def test_read_observations_and_a_plain_pyarrow_join_to_the_grasps(job_dir, raw):
    obs = read_observations(job_dir)
    assert obs.num_rows == len(raw)
    grasps = read_job(job_dir, columns=["grasp_id", "object_id", "object_scale_m", "split"])
    # pyarrow's join takes scalar columns only (the key and e.g. the split); pandas merges all
    joined = grasps.join(obs.select(["object_id", "object_scale_m", "split"]),
                         keys=["object_id", "object_scale_m"], right_suffix="_obs")
    assert joined.num_rows == grasps.num_rows  # every grasp has its object's observation at its scale
    assert joined["split"].to_pylist() == joined["split_obs"].to_pylist()
    merged = grasps.to_pandas().merge(pq.read_table(job_dir / "observations").to_pandas(),
                                      on=["object_id", "object_scale_m"], validate="many_to_one")
    assert len(merged) == grasps.num_rows and merged["surface_points_m"].map(len).eq(OBSERVATIONS["points"]).all()
    test = read_observations(job_dir, split="test")
    assert set(test["object_id"].to_pylist()) == {"b_ball.obj"} and test.num_rows == 2


def test_observation_grasp_pairs(job_dir, raw):
    ds = ObservationGraspDataset(job_dir, only_success=False, points=64, view_points=50)
    grasps = GraspDataset(job_dir, only_success=False)
    assert len(ds) == len(grasps) and ds.missing == 0
    by_key = {(r["object_id"], round(r["object_scale_m"], 6)): r for r in raw}
    for i in range(len(ds)):
        o, g = ds[i]
        assert torch.equal(g["grasp_qpos"], grasps[i]["grasp_qpos"])
        ref = by_key[(g["object_id"], round(float(g["object_scale_m"]), 6))]
        assert o["object_id"] == g["object_id"]
        np.testing.assert_array_equal(o["points"].numpy(), np.array(ref["surface_points_m"], np.float32)[:64])
        np.testing.assert_array_equal(o["bbox_m"].numpy(), np.array([ref["bbox_min_m"], ref["bbox_max_m"]], np.float32))
        assert o["view_points"].shape == (2, 50, 3)
        v0 = np.array(ref["view_points_m"][0], np.float32)
        np.testing.assert_array_equal(o["view_points"][0].numpy(), np.resize(v0, (50, 3)))
        np.testing.assert_array_equal(o["camera_poses"].numpy(), np.array(ref["camera_poses"], np.float32))
    ob, gb = next(iter(torch.utils.data.DataLoader(ds, batch_size=4)))
    assert ob["points"].shape == (4, 64, 3) and gb["grasp_qpos"].shape == (4, 7 + len(ds.joint_names))
    train = ObservationGraspDataset(job_dir, only_success=False, split="train")
    assert {train[i][1]["object_id"] for i in range(len(train))} == {"a_box.obj"}


def _copy(job_dir, tmp_path):
    shutil.copytree(job_dir, tmp_path / "job")
    return tmp_path / "job"


def test_a_damaged_observation_file_is_named_by_verify_and_the_readers(job_dir, tmp_path, capsys):
    from tests.workers.test_verify import flip_bit_in

    job = _copy(job_dir, tmp_path)
    p = sorted((job / "observations").glob("part-*.parquet"))[0]
    flip_bit_in(p, "surface_points_m")
    assert cli.main(["verify", str(job)]) == 1
    out = capsys.readouterr().out
    assert f"observations/{p.name}" in out and "sha256" in out
    with pytest.raises(ShardError, match=f"observations/{p.name}"):
        read_observations(job)
    p.write_bytes(p.read_bytes()[:-100])  # truncated: the cheap check finds it too
    with pytest.raises(ShardError, match="truncated"):
        read_observations(job)
    assert cli.main(["status", str(job)]) in (0, 1)
    assert f"observations/{p.name}" in capsys.readouterr().out


def test_a_job_without_observations_says_so(job_dir, tmp_path):
    job = _copy(job_dir, tmp_path)
    for e in (job / "ledger").glob("part-*.json"):
        entry = json.loads(e.read_text())
        entry["files"] = {k: v for k, v in entry["files"].items() if not k.startswith("observations/")}
        e.write_text(json.dumps(entry))
    shutil.rmtree(job / "observations")
    with pytest.raises(FileNotFoundError, match="no object observations"):
        read_observations(job)
    assert read_job(job).num_rows > 0
