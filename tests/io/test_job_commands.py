"""``datagen eval`` and ``datagen render`` on a job's own shards (rows' object_path is relative to
the job directory) and on a whole job directory."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pyarrow.parquet as pq
import pytest
import yaml

from datagen.cli import main
from datagen.eval.table import EVAL_COLUMNS
from datagen.io import read_job, shard_paths

pytestmark = pytest.mark.mujoco


def _clean(rows: list[dict]) -> list[dict]:
    return [{k: ("nan" if isinstance(v, float) and math.isnan(v) else
                 ["nan" if isinstance(x, float) and math.isnan(x) else x for x in v] if isinstance(v, list) else v)
             for k, v in r.items()} for r in rows]


@pytest.fixture(scope="module")
def job_eval_yaml(job_dir, tmp_path_factory):
    """The job's own evaluation config, as a ``--config`` YAML."""
    path = tmp_path_factory.mktemp("evalcfg") / "eval.yaml"
    path.write_text(yaml.safe_dump(json.loads((job_dir / "job.json").read_text())["config"]["eval"]))
    return path


def test_eval_of_a_shard_reproduces_the_pipeline(job_dir, job_eval_yaml, tmp_path):
    """Re-evaluating a shard where it lies, with the job's eval config, gives its rows' verdicts."""
    shard = shard_paths(job_dir)[0]
    out = tmp_path / "again.parquet"
    assert main(["eval", str(shard), "--out", str(out), "--config", str(job_eval_yaml)]) == 0
    cols = list(EVAL_COLUMNS)
    assert _clean(pq.read_table(out).select(cols).to_pylist()) == _clean(pq.read_table(shard).select(cols).to_pylist())


def test_eval_of_a_job_directory(job_dir, job_eval_yaml, tmp_path):
    out = tmp_path / "job.parquet"
    assert main(["eval", str(job_dir), "--out", str(out), "--config", str(job_eval_yaml)]) == 0
    got, ref = pq.read_table(out), read_job(job_dir)
    assert got["grasp_id"].to_pylist() == ref["grasp_id"].to_pylist()
    assert got["success"].to_pylist() == ref["success"].to_pylist()


def test_render_of_a_shard(job_dir, tmp_path):
    shard = shard_paths(job_dir)[0]
    res = subprocess.run([sys.executable, "-m", "datagen.cli", "render", str(shard), "--out", str(tmp_path),
                          "--rows", "0", "--width", "64", "--height", "48"], capture_output=True, text=True,
                         timeout=300, env=dict(os.environ))
    if res.returncode != 0 and "no offscreen OpenGL backend works here" in res.stderr:
        pytest.skip(f"no offscreen GL here: {res.stderr.strip()[-300:]}")
    assert res.returncode == 0, res.stderr
    (png,) = tmp_path.glob("grasp_000000_*.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_shard_copied_out_of_its_job_names_the_missing_object(job_dir, tmp_path, capsys):
    lone = tmp_path / "lone.parquet"
    lone.write_bytes(shard_paths(job_dir)[0].read_bytes())
    assert main(["eval", str(lone), "--out", str(tmp_path / "o.parquet")]) == 2
    err = capsys.readouterr().err
    assert "cannot read the processed object" in err and str(tmp_path) in err
