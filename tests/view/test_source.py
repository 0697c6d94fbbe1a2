"""Opening what `datagen view` shows: a job, a shard, a grasp table; filters; renamed columns."""

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from datagen.io import read_job
from datagen.view import ViewError, find_column, open_source


def test_job_shard_and_table_open_the_same_rows(job_dir, tmp_path):
    job = open_source(job_dir)
    reference = read_job(job_dir)
    assert len(job) == reference.num_rows > 0
    shard = open_source(next((Path(job_dir) / "shards").glob("part-*.parquet")))
    assert 0 < len(shard) <= len(job)
    assert shard.object_dir(0) == job.object_dir(job.values("grasp_id").index(shard.values("grasp_id")[0]))
    # a grasp table elsewhere: object_path absolute (as `datagen synth` writes it) resolves as is
    table = reference.set_column(reference.column_names.index("object_path"), "object_path",
                                 pa.array([str(job.object_dir(i)) for i in range(len(job))]))
    pq.write_table(table, tmp_path / "evaluated.parquet")
    other = open_source(tmp_path / "evaluated.parquet")
    for i in range(len(job)):
        assert other.object_dir(i) == job.object_dir(i)
        assert (job.object_dir(i) / "meta.json").is_file()
        np.testing.assert_array_equal(other.poses(i), job.poses(i))
    np.testing.assert_array_equal(job.poses(0)[1], np.asarray(reference["grasp_qpos"][0].as_py()))


def test_filters_match_arrow_compute(source, job_dir):
    t = read_job(job_dir)
    ok = source.select(verdict="success")
    assert list(ok) == list(np.flatnonzero(t["success"].to_numpy(zero_copy_only=False)))
    assert len(source.select(verdict="failure")) + len(ok) == len(source)
    obj = t["object_id"][0].as_py()
    scale = float(t["object_scale_m"][0].as_py())
    want = pc.and_(pc.equal(t["object_id"], obj), pc.equal(t["object_scale_m"], pa.scalar(scale, pa.float32())))
    got = source.select(object_id=obj, scale=f"{scale:.3f} m", hand="shadow", task="force_closure")
    assert list(got) == list(np.flatnonzero(want.to_numpy(zero_copy_only=False)))
    reason = source.reasons()[0]
    assert all(source.reasons()[i] == reason for i in source.select(reason=reason))
    assert len(source.select(hand="no such hand")) == 0


def test_renamed_columns_are_found(job_dir, tmp_path):
    """Tables from before the unit-suffix renames (schema v1: penetration, object_scale) open."""
    t = read_job(job_dir)
    renamed = t.rename_columns([{"penetration_m": "penetration", "object_scale_m": "object_scale"}.get(n, n)
                                for n in t.column_names])
    table = renamed.set_column(renamed.column_names.index("object_path"), "object_path",
                               pa.array([str(Path(job_dir) / p) for p in t["object_path"].to_pylist()]))
    pq.write_table(table, tmp_path / "renamed.parquet")
    src = open_source(tmp_path / "renamed.parquet")
    assert src.column("penetration_m") == "penetration" and src.column("object_scale_m") == "object_scale"
    assert [src.scale(i) for i in range(len(src))] == t["object_scale_m"].to_pylist()
    assert find_column(["a_deg"], "a") == "a_deg" and find_column(["b"], "b_m") == "b" and find_column([], "c") is None


def test_bad_sources_name_the_problem(tmp_path, job_dir):
    with pytest.raises(ViewError, match="not found"):
        open_source(tmp_path / "nothing.parquet")
    with pytest.raises(ViewError, match="not a datagen job"):
        open_source(tmp_path)
    pq.write_table(pa.table({"object_id": ["x"]}), tmp_path / "thin.parquet")
    with pytest.raises(ViewError, match="missing columns.*pregrasp_qpos"):
        open_source(tmp_path / "thin.parquet")
    (tmp_path / "junk.parquet").write_text("not parquet")
    with pytest.raises(ViewError, match="cannot be read as Parquet"):
        open_source(tmp_path / "junk.parquet")


def test_rows_are_read_from_their_shard(job_dir):
    """Only the index columns stay in memory; a shown row is read from its file, whichever it is."""
    src = open_source(job_dir)
    src._cached_files = 1
    reference = read_job(job_dir).to_pylist()
    assert len(src.files) > 1
    for i in list(range(len(src))) + list(range(len(src)))[::-1]:  # crossing files both ways
        row = src.row(i)
        assert row["grasp_id"] == reference[i]["grasp_id"]
        assert row["grasp_qpos"] == reference[i]["grasp_qpos"]
        assert src.value("object_id", i) == reference[i]["object_id"]
        assert src.value("verdict", i) == ("success" if reference[i]["success"] else "failure")
    assert len(src._tables) == 1
    assert src.options("object_id") == list(dict.fromkeys(r["object_id"] for r in reference))
    with pytest.raises(IndexError):
        src.row(len(src))
