"""``datagen eval`` and ``datagen render`` on a small grasp table."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from datagen.cli import main
from datagen.eval import EvalConfig, Evaluator
from datagen.eval.table import EVAL_COLUMNS
from datagen.objects import layout

from .grasps import box_grasp

pytestmark = pytest.mark.mujoco


def _processed_entry(pieces, root: Path) -> Path:
    """A processed-object cache entry (datagen.objects.layout) holding the test box as its piece."""
    entry = root / "entry_box"
    (entry / layout.PIECES_DIR).mkdir(parents=True, exist_ok=True)
    normalized = pieces.paths[0].read_bytes()
    (entry / layout.PIECES_DIR / layout.PIECE.format(i=0)).write_bytes(normalized)
    meta = {"meta_version": layout.META_VERSION, "object_id": "box", "status": "ok", "mesh_sha256": "0" * 64,
            "config_hash": "test", "piece_volumes": list(pieces.volumes)}
    (entry / layout.META).write_text(json.dumps(meta))
    return entry


@pytest.fixture(scope="module")
def table_path(shadow, box_dir):
    with Evaluator(shadow, EvalConfig()) as ev:
        pieces, good = box_grasp(ev, (0.03, 0.015, 0.03), 0.0, box_dir)
    entry = _processed_entry(pieces, box_dir)
    far = good.copy()
    far[:, 1] += 0.5
    rows = {"object_id": ["box"] * 3, "object_scale": [pieces.scale] * 3, "hand": ["shadow"] * 3,
            "task": ["force_closure", "force_closure", "turn_knob"], "object_path": ["entry_box"] * 3,
            "keep_me": [7, 8, 9], "w_t": [[0, 0, 0, 0, 0, 1.0]] * 3}
    for k, name in enumerate(("pregrasp_qpos", "grasp_qpos", "squeeze_qpos")):
        rows[name] = pa.array([g[k].astype(np.float32).tolist() for g in (good, far, good)],
                              type=pa.list_(pa.float32()))
    path = box_dir / "grasps.parquet"
    pq.write_table(pa.table(rows), path)
    return path


@pytest.mark.slow
def test_eval_cli_adds_columns(table_path, tmp_path):
    out = tmp_path / "evaluated.parquet"
    assert main(["eval", str(table_path), "--out", str(out)]) == 0
    t = pq.read_table(out)
    assert t.column("keep_me").to_pylist() == [7, 8, 9]
    assert set(EVAL_COLUMNS) <= set(t.column_names)
    assert t.column("reason").to_pylist() == ["ok", "no_contact", "ok"]
    assert t.column("success").to_pylist() == [True, False, True]
    assert t.column("eval_test").to_pylist() == ["six_direction", "six_direction", "turn_knob"]
    assert [len(x) for x in t.column("dir_success").to_pylist()] == [6, 6, 1]
    assert [len(x) for x in t.column("finger_distance_m").to_pylist()] == [5, 5, 5]
    # two worker processes give the same table
    out2 = tmp_path / "evaluated2.parquet"
    assert main(["eval", str(table_path), "--out", str(out2), "--workers", "2"]) == 0
    cols = list(EVAL_COLUMNS)
    assert repr(pq.read_table(out2).select(cols).to_pylist()) == repr(t.select(cols).to_pylist())  # NaN-safe


def test_eval_cli_reports_missing_columns(tmp_path, capsys):
    bad = tmp_path / "bad.parquet"
    pq.write_table(pa.table({"object_id": ["a"]}), bad)
    assert main(["eval", str(bad), "--out", str(tmp_path / "o.parquet")]) == 2
    assert "missing columns" in capsys.readouterr().err


@pytest.mark.slow
def test_render_cli_writes_png(table_path, tmp_path):
    env = {**os.environ, "MUJOCO_GL": "osmesa"}
    res = subprocess.run([sys.executable, "-m", "datagen.cli", "render", str(table_path), "--out", str(tmp_path),
                          "--rows", "0", "--width", "160", "--height", "120"], env=env, capture_output=True,
                         text=True, timeout=120)
    if res.returncode != 0 and "GL context" in res.stderr:
        pytest.skip(f"no offscreen GL here: {res.stderr.strip()[-200:]}")
    assert res.returncode == 0, res.stderr
    png = tmp_path / "grasp_000000_box.png"
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert (w, h) == (3 * 160, 2 * 120)
