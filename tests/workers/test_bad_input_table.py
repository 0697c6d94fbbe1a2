"""The bad-input tables of docs/bad-input.md are true: every row's input gives what the row
says. Each row's first cell names a scenario below; the set of rows and scenarios must match.

A command row says ``exit N`` and quotes the message; an object row says ``failure row
`stage:reason` `` and quotes the failure message. In a quote, ``...`` stands for any text (a path)."""

from __future__ import annotations

import importlib
import os
import re
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import trimesh

from datagen import cli
from workers.job import JobDir
from workers.finished import merge_failures
from workers.setup import prepare_manifest

from .conftest import tiny_config
from .test_shard import run_all

PAGE = Path(__file__).resolve().parents[2] / "docs" / "bad-input.md"


def table_rows() -> dict[str, str]:
    """input cell -> what-you-see cell, from the page's bad-input tables."""
    section = PAGE.read_text().split("\n## ", 1)[0]  # the tables above the details
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else []
        if len(cells) == 2 and not set(cells[0]) <= set("-: ") and cells[0] != "input":
            rows[cells[0]] = cells[1]
    return rows


# ------------------------------------------------------------------ scenarios
def _box(path: Path, extents=(0.1, 0.06, 0.04)) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents).export(path)
    return path


def _src(tmp: Path) -> str:
    _box(tmp / "src" / "a.obj")
    return f"dir:{tmp / 'src'}"


def _run(tmp, capsys, *extra, config: str | None = None, out: Path | None = None) -> tuple[int, str]:
    args = ["run", "--out", str(out or tmp / "job"), "--source", _src(tmp), "--no-progress"]
    if config is not None:
        (tmp / "job.yaml").write_text(config)
        args += ["--config", str(tmp / "job.yaml")]
    code = cli.main(args + list(extra))
    return code, capsys.readouterr().err


def _file(path: Path) -> Path:
    path.write_text("x")
    return path


def _folder(path: Path) -> Path:
    path.mkdir()
    (path / "notes.txt").write_text("no mesh here")
    return path


def _manifest_check(tmp, capsys, text: str) -> tuple[int, str]:
    (tmp / "m.jsonl").write_text(text)
    code = cli.main(["manifest", "check", str(tmp / "m.jsonl")])
    return code, capsys.readouterr().err


def _interrupted(tmp, capsys, monkeypatch):
    import workers.run

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(workers.run, "run_job", ctrl_c)
    return _run(tmp, capsys)


def _ctrl_c(monkeypatch, module: str, name: str) -> None:
    """``module.name`` raises KeyboardInterrupt, as a Ctrl-C there does (a real SIGINT: tests/test_cli.py)."""
    import importlib

    def ctrl_c(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib.import_module(module), name, ctrl_c)


def _interrupted_command(tmp, capsys, monkeypatch, where: tuple[str, str], args: list[str]):
    _ctrl_c(monkeypatch, *where)
    code = cli.main(args)
    return code, capsys.readouterr().err


def _no_gl_run(tmp, capsys, monkeypatch):
    import datagen.gl
    from datagen.objects import observations

    def no_gl():
        raise datagen.gl.GLUnavailable("no offscreen OpenGL backend works here: egl: libEGL not found (...)")

    monkeypatch.setattr(datagen.gl, "select_backend", no_gl)
    monkeypatch.setattr(observations, "_resolved", {})
    return _run(tmp, capsys, config="observations: {renderer: mujoco}\n")


def _different_job(tmp, capsys):
    JobDir(tmp / "job").init(tiny_config(_src(tmp), seed=5))
    return _run(tmp, capsys)


def _locked(tmp, capsys):
    other = JobDir(tmp / "job")
    other.lock()
    try:
        return _run(tmp, capsys)
    finally:
        other.unlock()


def _read_only_out(tmp, capsys):
    ro = tmp / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("running as root: a read-only directory cannot be made")
        return _run(tmp, capsys, out=ro / "job")
    finally:
        ro.chmod(0o700)


def _synth_num_0(tmp, capsys):
    code = cli.main(["synth", "--object", str(_box(tmp / "box.obj")), "--num", "0", "--out", str(tmp / "g.parquet")])
    return code, capsys.readouterr().err


_CACHE: dict[str, str] = {}  # the session's objects cache (set by the tests below)


def _fifo(tmp: Path) -> Path:
    os.mkfifo(tmp / "fifo")
    return tmp / "fifo"


def _finished_job(tmp: Path) -> JobDir:
    """A copy, in ``tmp/j`` (not ``tmp/job``: exit-2 rows check that none is made), of a finished
    one-object job (its shard run in this process once per session)."""
    import shutil

    built = Path(_CACHE["dir"]).parent / "table_job"
    if not (built / "j" / "ledger" / "part-00000.json").is_file():
        shutil.rmtree(built, ignore_errors=True)
        run_all(built / "j", tiny_config(_src(built), count=1), _CACHE["dir"])
    shutil.copytree(built / "j", tmp / "j")
    return JobDir(tmp / "j")


def _damaged(tmp, capsys, damage, command: str) -> tuple[int, str]:
    job = _finished_job(tmp)
    damage(job)
    capsys.readouterr()
    code = cli.main([command, str(job.path)])
    out = capsys.readouterr()
    return code, out.out + out.err


def _flip(job: JobDir) -> None:
    from .test_verify import flip_bit_in

    flip_bit_in(job.shard_path(0), "grasp_qpos")


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _eval_outside(tmp, capsys):
    import pyarrow as pa

    pose = pa.array([[0.0] * 7], type=pa.list_(pa.float32()))
    pq.write_table(pa.table({"object_id": ["a.obj"], "object_scale_m": [0.08], "hand": ["shadow"],
                             "task": ["force_closure"], "pregrasp_qpos": pose, "grasp_qpos": pose,
                             "squeeze_qpos": pose, "object_path": ["/etc"]}), tmp / "g.parquet")
    code = cli.main(["eval", str(tmp / "g.parquet"), "--out", str(tmp / "e.parquet")])
    return code, capsys.readouterr().err


def _terminated(tmp, capsys, monkeypatch):
    from datagen._interrupt import Terminated

    def sigterm(*a, **k):
        raise Terminated  # what SIGTERM raises in the driver (a real one: test_run.py)

    monkeypatch.setattr(importlib.import_module("workers.run"), "run_job", sigterm)
    return _run(tmp, capsys)


COMMANDS = {
    "`run --manifest /dev/zero`": lambda t, c, m: _run(t, c, "--manifest", "/dev/zero"),
    "`run --config` a FIFO": lambda t, c, m: _run(t, c, "--config", str(_fifo(t))),
    "config with a key given twice": lambda t, c, m: _run(t, c, config="seed: 1\nseed: 2\n"),
    "`run --num-cpus -1`": lambda t, c, m: _run(t, c, "--num-cpus", "-1"),
    "`eval` of a row whose `object_path` is `/etc`": lambda t, c, m: _eval_outside(t, c),
    "a shard with one flipped bit": lambda t, c, m: _damaged(t, c, _flip, "verify"),
    "an edited `manifest.jsonl`": lambda t, c, m: _damaged(
        t, c, lambda j: j.manifest_path.write_text(j.manifest_path.read_text().replace("train", "TRAIN", 1)), "verify"),
    "a deleted shard": lambda t, c, m: _damaged(t, c, lambda j: j.shard_path(0).unlink(), "status"),
    "a truncated shard": lambda t, c, m: _damaged(t, c, lambda j: _truncate(j.shard_path(0)), "status"),
    "an empty ledger entry": lambda t, c, m: _damaged(t, c, lambda j: j.ledger_path(0).write_text(""), "status"),
    "a truncated `job.json`": lambda t, c, m: _damaged(t, c, lambda j: _truncate(j.path / "job.json"), "status"),
    "SIGTERM during `run`": lambda t, c, m: _terminated(t, c, m),
    "`run --hand nohand`": lambda t, c, m: _run(t, c, "--hand", "nohand"),
    "`run --tasks nope`": lambda t, c, m: _run(t, c, "--tasks", "nope"),
    "`run --seed -1`": lambda t, c, m: _run(t, c, "--seed", "-1"),
    "`run --source ftp:x`": lambda t, c, m: _run(t, c, "--source", "ftp:x"),
    "`run --source dir:` of a folder without meshes": lambda t, c, m: _run(t, c, "--source", f"dir:{_folder(t / 'e')}"),
    "`run --manifest missing.jsonl`": lambda t, c, m: _run(t, c, "--manifest", str(t / "missing.jsonl")),
    "config `grasps_per_object: many`": lambda t, c, m: _run(t, c, config="grasps_per_object: many\n"),
    "config `cuont: 3`": lambda t, c, m: _run(t, c, config="cuont: 3\n"),
    "config `observations: {renderer: opengl}`": lambda t, c, m: _run(t, c, config="observations: {renderer: opengl}\n"),
    "config `observations: {renderer: mujoco}` without OpenGL": lambda t, c, m: _no_gl_run(t, c, m),
    "config with a `!!python/...` tag": lambda t, c, m: _run(
        t, c, config="hand: !!python/object/apply:os.getcwd []\n"),
    "config with YAML aliases": lambda t, c, m: _run(
        t, c, config="a: &a [0.06, 0.06, 0.06]\nscales: [*a, *a]\n"),
    "`--out` an existing file": lambda t, c, m: _run(t, c, out=_file(t / "f")),
    "`--out` in a read-only folder": lambda t, c, m: _read_only_out(t, c),
    "`--out` of another job's config": lambda t, c, m: _different_job(t, c),
    "`--cache` an existing file": lambda t, c, m: _run(t, c, "--cache", str(_file(t / "c"))),
    "`--out` of a running job": lambda t, c, m: _locked(t, c),
    "Ctrl-C during `run`": lambda t, c, m: _interrupted(t, c, m),
    "Ctrl-C during `prepare`": lambda t, c, m: _interrupted_command(
        t, c, m, ("datagen.objects.prepare", "prepare"), ["prepare", "--manifest", str(_file(t / "m.jsonl"))]),
    "Ctrl-C during `synth`": lambda t, c, m: _interrupted_command(
        t, c, m, ("datagen.pipeline.api", "load_object"),
        ["synth", "--object", str(_box(t / "box.obj")), "--out", str(t / "g.parquet")]),
    "Ctrl-C during `eval`": lambda t, c, m: _interrupted_command(
        t, c, m, ("datagen.eval.table", "read_grasps"), ["eval", str(t / "g.parquet"), "--out", str(t / "e.parquet")]),
    "manifest line nested 100000 deep": lambda t, c, m: _manifest_check(t, c, "[" * 100_000 + "]" * 100_000 + "\n"),
    "`synth --num 0`": lambda t, c, m: _synth_num_0(t, c),
}


def _shard_failure(tmp: Path, cache: str, damage, timeout_s: float = 120.0, before: bool = False) -> dict:
    """Build a one-object job, damage its file (after the manifest, or ``before`` it), run its
    shard: the failure."""
    src = _src(tmp)
    if before:
        damage(tmp / "src" / "a.obj")
    cfg = tiny_config(src, count=1, object_timeout_s=timeout_s)
    job = JobDir(tmp / "job")
    job.init(cfg)
    prepare_manifest(job, cfg)
    if not before:
        damage(tmp / "src" / "a.obj")
    run_all(job.path, cfg, cache)
    assert not job.shard_path(0).exists()  # no rows
    (row,) = pq.read_table(job.failures_path).to_pylist()
    return row


def _manifest_failure(tmp: Path, make) -> dict:
    src = _src(tmp)
    make(tmp / "src" / "x.obj", tmp)
    job = JobDir(tmp / "job")
    cfg = tiny_config(src, count=2)
    job.init(cfg)
    entries = prepare_manifest(job, cfg)
    assert [e.id for e in entries] == ["a.obj"]
    (row,) = merge_failures(job).to_pylist()
    return row


def _outside(p: Path, tmp: Path):
    p.symlink_to(_box(tmp / "outside.obj"))


OBJECTS = {
    "mesh file deleted after the manifest was built": lambda t, cache: _shard_failure(t, cache, Path.unlink),
    "mesh file changed after the manifest was built": lambda t, cache: _shard_failure(
        t, cache, lambda p: _box(p, (0.2, 0.1, 0.1))),
    "a file that is not a mesh": lambda t, cache: _shard_failure(t, cache, lambda p: p.write_text("hello\n"),
                                                                  before=True),
    "processing over `object_timeout_s`": lambda t, cache: _shard_failure(
        t, str(t / "fresh_cache"), lambda p: None, timeout_s=0.01),
    "a symlink out of the source folder": lambda t, cache: _manifest_failure(t, _outside),
    "a folder named `x.obj`": lambda t, cache: _manifest_failure(t, lambda p, tmp: p.mkdir()),
    "a symlink loop named `x.obj`": lambda t, cache: _manifest_failure(t, lambda p, tmp: p.symlink_to(p)),
}


def _matches(quote: str, text: str) -> bool:
    pattern = ".*".join(re.escape(part) for part in quote.split("..."))
    return re.search(pattern, text, re.S) is not None


def test_every_row_has_a_scenario_and_back():
    assert set(table_rows()) == set(COMMANDS) | set(OBJECTS) | set(ELSEWHERE)


# rows a test elsewhere checks (with its job on Ray), by the same rules as test_command_row_is_true
ELSEWHERE = {"the disk under `--out` fills up": "test_verify.py::test_a_full_disk_is_one_line_and_the_rerun_finishes"}


@pytest.mark.parametrize("row", sorted(COMMANDS))
def test_command_row_is_true(row, tmp_path, capsys, monkeypatch, cache_dir):
    _CACHE["dir"] = cache_dir
    cell = table_rows()[row]
    found = re.search(r"exit (\d+)", cell)
    want_exit = int(found.group(1)) if found else 0
    quote = re.findall(r"`([^`]*)`", cell)[-1]
    code, err = COMMANDS[row](tmp_path, capsys, monkeypatch)
    assert code == want_exit, err
    assert _matches(quote, err), err
    assert "Traceback" not in err
    if not cell.startswith(("`status`", "`verify`")):  # their report has a line per problem
        assert len(err.strip().splitlines()) <= 2, err  # one clear line
    if want_exit == 2 and "another job" not in row and "running job" not in row:
        assert not (tmp_path / "job").exists()  # refused before a job directory exists


@pytest.mark.parametrize("row", sorted(OBJECTS))
def test_object_row_is_true(row, tmp_path, cache_dir):
    cell = table_rows()[row]
    stage, reason = re.search(r"failure row `(\w+):(\w+)`", cell).groups()
    quote = re.findall(r"`([^`]*)`", cell)[-1]
    got = OBJECTS[row](tmp_path, cache_dir)
    assert (got["stage"], got["reason"]) == (stage, reason), got
    assert _matches(quote, got["message"]), got["message"]
