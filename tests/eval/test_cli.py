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
    rows = {"object_id": ["box"] * 3, "object_scale_m": [pieces.scale] * 3, "hand": ["shadow"] * 3,
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


def test_eval_reads_objects_only_from_the_table_dir_or_the_cache(table_path, tmp_path, capsys, monkeypatch):
    from datagen.gl import GLUnavailable, select_backend

    try:
        select_backend()
        commands = ("eval", "render")
    except GLUnavailable:  # render refuses first for want of GL
        commands = ("eval",)
    monkeypatch.setenv("DATAGEN_CACHE", str(tmp_path / "cache"))
    entry = table_path.parent / "entry_box"
    one = pq.read_table(table_path).slice(0, 1)
    for where in ("/etc", "../../etc", str(entry)):  # the last: another table's object, by absolute path
        path = tmp_path / "t.parquet"
        pq.write_table(one.set_column(one.schema.get_field_index("object_path"), "object_path", pa.array([where])),
                       path)
        for command in commands:
            out = tmp_path / ("o.parquet" if command == "eval" else "r")
            assert main([command, str(path), "--out", str(out)]) == 2
            err = capsys.readouterr().err
            assert f"row 0 (object 'box'): object_path {where!r} resolves to " in err, err
            assert f"outside {tmp_path} and {tmp_path / 'cache'} (pass --allow-outside" in err, err
            assert not (tmp_path / "o.parquet").exists() and not (tmp_path / "r").exists()
    # the objects cache is allowed, and --allow-outside lifts the check (the row is then evaluated)
    assert main(["eval", str(path), "--out", str(tmp_path / "o.parquet"), "--cache", str(entry.parent)]) == 0
    assert main(["eval", str(path), "--out", str(tmp_path / "o2.parquet"), "--allow-outside"]) == 0
    assert pq.read_table(tmp_path / "o2.parquet")["reason"].to_pylist() == ["ok"]


def _datagen(args: list[str], **env) -> subprocess.CompletedProcess:
    """``python -m datagen.cli ARGS`` in a fresh process, environment changes in ``env`` (None unsets)."""
    e = {**os.environ, **{k: v for k, v in env.items() if v is not None}}
    for k in [k for k, v in env.items() if v is None]:
        e.pop(k, None)
    return subprocess.run([sys.executable, "-m", "datagen.cli", *args], env=e, capture_output=True, text=True,
                          timeout=300)


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


@pytest.mark.slow
@pytest.mark.parametrize("gl", [None, "osmesa"])
def test_render_cli_writes_png(table_path, tmp_path, gl):
    """Unset, the backend is chosen (egl, then osmesa); an unusable MUJOCO_GL (osmesa without
    libOSMesa) is dropped with a warning. With no working backend at all the test skips."""
    res = _datagen(["render", str(table_path), "--out", str(tmp_path), "--rows", "0", "--width", "160",
                    "--height", "120"], MUJOCO_GL=gl)
    if res.returncode != 0 and "no offscreen OpenGL backend works here" in res.stderr:
        pytest.skip(f"no offscreen GL here: {res.stderr.strip()[-300:]}")
    assert res.returncode == 0, res.stderr
    assert _png_size(tmp_path / "grasp_000000_box.png") == (3 * 160, 2 * 120)


def test_render_says_when_no_backend_works(table_path, tmp_path):
    """PyOpenGL pinned to a platform neither egl nor osmesa accepts: both probes fail, the command
    exits 2 naming each backend and the remedy, and writes nothing."""
    res = _datagen(["render", str(table_path), "--out", str(tmp_path / "r"), "--rows", "0"],
                   MUJOCO_GL=None, PYOPENGL_PLATFORM="glx")
    assert res.returncode == 2, res.stderr
    assert "no offscreen OpenGL backend works here" in res.stderr
    assert "egl:" in res.stderr and "osmesa:" in res.stderr and "libosmesa6" in res.stderr
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("gl", ["osmesa", "no-such-backend"])
def test_wrong_mujoco_gl_does_not_break_simulation(table_path, tmp_path, gl):
    """`datagen eval` imports mujoco but does not render: a MUJOCO_GL that mujoco cannot load is
    dropped with a warning (if the machine does have libOSMesa, osmesa is simply used)."""
    out = tmp_path / "e.parquet"
    res = _datagen(["eval", str(table_path), "--out", str(out)], MUJOCO_GL=gl)
    assert res.returncode == 0, res.stderr
    assert pq.read_table(out).column("success").to_pylist() == [True, False, True]
    if gl != "osmesa":
        assert f"MUJOCO_GL={gl!r} is not a backend mujoco knows" in res.stderr


def _all_parsers():
    import argparse

    from datagen.cli import build_parser

    todo, seen = [("datagen", build_parser())], []
    while todo:
        name, p = todo.pop()
        seen.append((name, p))
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                todo += [(f"{name} {n}", sp) for n, sp in a.choices.items()]
    return seen


def test_every_option_has_help_and_shows_its_default():
    import argparse

    missing, hidden = [], []
    for name, p in _all_parsers():
        text = p.format_help()
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction) or a.help == argparse.SUPPRESS:
                continue
            if a.help is None or not a.help.strip():
                missing.append(f"{name} {'/'.join(a.option_strings) or a.dest}")
            elif a.option_strings and a.default not in (None, False, "==SUPPRESS==") and "default" not in a.help:
                if f"(default: {a.default})" not in " ".join(text.split()):
                    hidden.append(f"{name} {a.option_strings[0]}")
    assert not missing, f"options without help: {missing}"
    assert not hidden, f"defaults not shown: {hidden}"


def test_version_and_listings(capsys):
    import datagen

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"datagen {datagen.__version__}"
    from datagen.hands.load import BUILTIN_HANDS
    from datagen.tasks import builtin_tasks

    assert main(["hands"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == list(BUILTIN_HANDS)
    assert all(len(ln.split(None, 2)) == 3 for ln in lines)  # name, availability, description
    assert main(["tasks"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == builtin_tasks()
    knob = next(ln for ln in lines if ln.startswith("turn_knob2 "))
    assert "object knob2" in knob and "Turn a round knob" in knob
