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
    cfg, obs = front["configs"]
    files = cfg["data_files"][0]["path"]
    assert cfg["config_name"] == "default"
    assert sorted(job_dir.glob(files)) == sorted((job_dir / "shards").glob("*.parquet"))
    assert obs["config_name"] == "observations"
    assert sorted(job_dir.glob(obs["data_files"][0]["path"])) == sorted((job_dir / "observations").glob("*.parquet"))
    assert "## Object observations" in card and "4 rows, one per object and scale (2 objects)" in card
    assert "examples/learn_grasps.py" in card
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
    o = datasets.load_dataset(str(job_dir), "observations", split="train", cache_dir=str(tmp_path / "hf"))
    assert sorted(zip(o["object_id"], o["object_scale_m"])) == sorted(
        (r["object_id"], r["object_scale_m"]) for r in pq.read_table(job_dir / "observations").to_pylist())


def _all_successful(job_dir, tmp_path):
    """A copy of the tiny job (whose 20-iteration grasps all fail) with every row marked
    successful, its ledger entries rewritten to vouch for the new files."""
    import json
    import shutil

    import pyarrow as pa

    from datagen.io import integrity

    job = tmp_path / "job"
    shutil.copytree(job_dir, job)
    for p in sorted((job / "shards").glob("*.parquet")):
        t = pq.read_table(p)
        t = t.set_column(t.schema.get_field_index("success"), "success", pa.array([True] * t.num_rows))
        pq.write_table(t, p, **integrity.WRITE_OPTIONS)
        led = job / "ledger" / p.name.replace(".parquet", ".json")
        entry = json.loads(led.read_text())
        entry["files"][f"shards/{p.name}"] = integrity.file_record(p)
        led.write_text(json.dumps(entry))
    return job


def test_status_diversity_per_task_and_scale(job_dir, tmp_path, capsys):
    """`datagen status --diversity` against the diversity of the successes read straight from the
    shards (pyarrow) and grouped here, with the hand's joint limits."""
    import json
    import math

    import numpy as np

    from datagen import cli
    from datagen.eval.diversity import grasp_diversity
    from datagen.hands import load_hand

    assert cli.main(["status", "--diversity", "--json", str(job_dir)]) == 0
    none = json.loads(capsys.readouterr().out)["diversity"]
    assert none == []  # no successes: no group
    job_dir = _all_successful(job_dir, tmp_path)
    assert cli.main(["status", "--diversity", "--json", str(job_dir)]) == 0
    got = json.loads(capsys.readouterr().out)["diversity"]
    rows = [r for p in sorted((job_dir / "shards").glob("*.parquet")) for r in pq.read_table(p).to_pylist()
            if r["success"]]
    hand = load_hand(rows[0]["hand"])
    lo, hi = hand.joint_lower.numpy(), hand.joint_upper.numpy()
    scales = sorted({round(r["object_scale_m"], 6) for r in rows})
    assert [(g["task"], g["object_scale_m"]) for g in got] == [("force_closure", s) for s in scales] + [
        ("force_closure", None)]
    for g in got:
        sel = [r["grasp_qpos"] for r in rows
               if g["object_scale_m"] is None or round(r["object_scale_m"], 6) == g["object_scale_m"]]
        want = grasp_diversity(np.array(sel), lo, hi)
        assert g["n"] == want.n and g["hand"] == rows[0]["hand"]
        assert g["joint_entropy"] == pytest.approx(want.joint_entropy)
        assert [math.nan if x is None else x for x in g["pca"]] == pytest.approx(list(want.pca), nan_ok=True)
    assert cli.main(["status", "--diversity", str(job_dir)]) == 0
    text = capsys.readouterr().out
    assert "diversity of the successful grasps" in text and "max ln 32 = 3.47" in text
