"""A job's shards read by datagen.io and by third-party readers with no project code, each checked
against a direct pyarrow.parquet read of the files."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest
import torch

from datagen.io import GraspDataset, joint_names, open_dataset, read_job, shard_paths

# every test reads the session's tiny job (built by Ray-free shard runs, ~30 s)
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def raw(job_dir):
    """Reference: every shard file read on its own."""
    tables = [pq.read_table(p) for p in sorted((job_dir / "shards").glob("part-*.parquet"))]
    rows = [r for t in tables for r in t.to_pylist()]
    assert len(rows) == 2 * 2 * 3  # two good objects x two scales x three grasps
    return rows


def test_read_job_matches_the_files(job_dir, raw):
    t = read_job(job_dir)
    assert sorted(t["grasp_id"].to_pylist()) == sorted(r["grasp_id"] for r in raw)
    ok = read_job(job_dir, only_success=True)
    assert ok.num_rows == sum(bool(r["success"]) for r in raw)
    assert open_dataset(job_dir).count_rows() == len(raw)
    names = joint_names(job_dir)
    assert len(names) + 7 == len(raw[0]["grasp_qpos"])
    assert names == json.loads(pq.read_schema(shard_paths(job_dir)[0]).metadata[b"datagen.joint_names"])
    assert all(r["joint_names"] == names for r in raw)  # each row names its joints
    manifest = [json.loads(ln) for ln in (job_dir / "manifest.jsonl").read_text().splitlines() if ln.strip()]
    split = {e["id"]: e["split"] for e in manifest}
    assert all(r["split"] == split[r["object_id"]] for r in raw)  # taken from the manifest
    assert {r["split"] for r in raw} == {"train", "test"}


def test_an_unknown_column_is_named_not_a_damaged_shard(job_dir):
    """A column the schema lacks is the caller's mistake: one line naming it, not ShardError's
    'damaged, rerun the job'."""
    assert read_job(job_dir, columns=["object_scale_m"]).column_names == ["object_scale_m"]
    with pytest.raises(ValueError, match=r"no column 'scale' in .*object_id") as exc:
        read_job(job_dir, columns=["object_scale_m", "scale"])
    assert "damaged" not in str(exc.value)


def test_unfinished_shards_are_not_read(job_dir, tmp_path):
    import shutil

    copy = tmp_path / "job"
    shutil.copytree(job_dir, copy)
    (copy / "ledger" / "part-00000.json").unlink()  # shard 2 (the bad object) has no rows, no file
    assert [p.name for p in shard_paths(copy)] == ["part-00001.parquet"]
    with pytest.raises(FileNotFoundError, match="not a datagen job"):
        shard_paths(tmp_path)


def test_torch_dataset(job_dir, raw):
    ds = GraspDataset(job_dir, only_success=False)
    assert len(ds) == len(raw)
    by_id = {r["grasp_id"]: r for r in raw}
    table = read_job(job_dir, columns=["grasp_id"])
    for i in range(len(ds)):
        ref = by_id[table["grasp_id"][i].as_py()]
        item = ds[i]
        assert torch.equal(item["grasp_qpos"], torch.tensor(ref["grasp_qpos"], dtype=torch.float32))
        assert bool(item["success"]) == ref["success"]
        assert (job_dir / ref["object_path"]).resolve() == __import__("pathlib").Path(item["object_path"])
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=4)))
    assert batch["squeeze_qpos"].shape == (4, 7 + len(ds.joint_names))
    assert len(GraspDataset(job_dir)) == sum(bool(r["success"]) for r in raw)


def test_pyarrow_dataset_reads_the_shards(job_dir, raw):
    import pyarrow.dataset as pads

    t = pads.dataset(str(job_dir / "shards"), format="parquet").to_table()
    assert sorted(t["grasp_id"].to_pylist()) == sorted(r["grasp_id"] for r in raw)


def test_pandas_reads_the_shards(job_dir, raw):
    pd = pytest.importorskip("pandas")
    df = pd.read_parquet(job_dir / "shards")
    assert sorted(df["grasp_id"]) == sorted(r["grasp_id"] for r in raw)
    ref = {r["grasp_id"]: r["penetration_m"] for r in raw}
    for gid, pen in zip(df["grasp_id"], df["penetration_m"]):
        assert (math.isnan(pen) and math.isnan(ref[gid])) or pen == pytest.approx(ref[gid])


def test_duckdb_reads_the_shards(job_dir, raw):
    duckdb = pytest.importorskip("duckdb")
    con = duckdb.connect()
    n, ok = con.execute(f"select count(*), sum(success::int) from '{job_dir}/shards/*.parquet'").fetchone()
    assert (n, ok) == (len(raw), sum(bool(r["success"]) for r in raw))
    (q,) = con.execute(f"select grasp_qpos from '{job_dir}/shards/*.parquet' where grasp_id = "
                      f"'{raw[0]['grasp_id']}'").fetchone()
    assert np.allclose(q, raw[0]["grasp_qpos"])


def test_hugging_face_datasets_reads_the_shards(job_dir, raw, tmp_path, monkeypatch):
    datasets = pytest.importorskip("datasets")
    monkeypatch.setenv("HF_DATASETS_OFFLINE", "1")
    d = datasets.load_dataset("parquet", data_files=sorted(str(p) for p in (job_dir / "shards").glob("*.parquet")),
                              split="train", cache_dir=str(tmp_path / "hf"))
    assert d.num_rows == len(raw)
    assert sorted(d["grasp_id"]) == sorted(r["grasp_id"] for r in raw)
