"""The dataset card of a finished job: front matter, the column table from the schema, captioned
renders of successes and failures across objects."""

from __future__ import annotations

import pyarrow.parquet as pq
import pytest
import yaml

from schemas import columns
from workers.report import pick_renders, write_report


def test_pick_renders_alternates_and_spreads_over_objects():
    success = [True, True, False, True, False, False]
    objects = ["a", "a", "a", "b", "b", "c"]
    got = pick_renders(success, objects, 4)
    assert [success[i] for i in got] == [True, False, True, False]
    assert len({objects[i] for i in got}) == 3  # a, b, c all shown
    assert pick_renders([True] * 3, ["a", "b", "c"], 5) == [0, 1, 2]  # no failures: successes only
    assert pick_renders([], [], 3) == []


@pytest.mark.mujoco
def test_card(job_dir):
    card = write_report(job_dir, renders=2).read_text()
    front = yaml.safe_load(card.split("---\n")[1])
    (cfg,) = front["configs"]
    files = cfg["data_files"][0]["path"]
    assert sorted(job_dir.glob(files)) == sorted((job_dir / "shards").glob("*.parquet"))
    for c in columns("evaluated"):  # every column in the table, with its unit
        line = next(ln for ln in card.splitlines() if ln.startswith(f"| `{c['name']}` |"))
        assert f"| {c.get('unit', '')} |" in line
    rows = pq.read_table(next((job_dir / "shards").glob("*.parquet"))).to_pylist()
    assert f"`{rows[0]['joint_names'][0]}`" in card
    # the test behind `success`: the tiny job's own hold (hold_steps 50 x 4 ms, TINY_EVAL), the
    # evaluator's defaults for the rest (thresholds, the early pass)
    test = next(ln for ln in card.splitlines() if ln.startswith("- MuJoCo test:"))
    assert "for 0.2 s" in test and "5 cm and 15 deg" in test and "`settle_safety` 12" in test
    pics = sorted((job_dir / "renders").glob("*.png")) if (job_dir / "renders").is_dir() else []
    if pics:
        assert len(pics) == 2
        captions = [ln for ln in card.splitlines() if ln[:3] in ("1. ", "2. ")]
        assert len(captions) == 2 and all("object `" in c and "task `" in c for c in captions)
    else:
        assert "No grasp pictures" in card


@pytest.mark.mujoco
def test_hugging_face_loads_the_job_directory_by_its_card(job_dir, tmp_path, monkeypatch):
    """The front matter's data_files select the shards (not failures.parquet) when the job
    directory itself is loaded, as a dataset repository would be."""
    datasets = pytest.importorskip("datasets")
    monkeypatch.setenv("HF_DATASETS_OFFLINE", "1")
    write_report(job_dir, renders=0)
    d = datasets.load_dataset(str(job_dir), split="train", cache_dir=str(tmp_path / "hf"))
    ref = [r for p in sorted((job_dir / "shards").glob("*.parquet")) for r in pq.read_table(p).to_pylist()]
    assert sorted(d["grasp_id"]) == sorted(r["grasp_id"] for r in ref)
    assert d[0]["joint_names"] == ref[0]["joint_names"]
