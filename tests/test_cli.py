"""Ctrl-C in the long-running commands: a real SIGINT sent to the command's process group (as a
terminal sends it) gives exit 130, one line saying what was kept and how to go on, no traceback
(from the command or its child processes), no half-written output, and no process left running."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import trimesh

from datagen import cli

REPO = Path(__file__).resolve().parents[1]


def _leaves(parser: argparse.ArgumentParser):
    """(name, parser) of every command that runs something: sub-commands of sub-commands too."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                inner = [a for a in sub._actions if isinstance(a, argparse._SubParsersAction)]
                yield from (((f"{name} {n}", p) for n, p in _leaves(sub)) if inner else [(name, sub)])


def test_every_command_says_what_an_interrupt_keeps():
    leaves = dict(_leaves(cli.build_parser()))
    assert {"run", "prepare", "synth", "eval", "manifest build"} <= set(leaves)
    assert [name for name, p in leaves.items() if not p.get_default("interrupted")] == []


def test_the_interrupted_line_names_the_command_and_its_output():
    args = cli.build_parser(["eval"]).parse_args(["eval", "g.parquet", "--out", "e.parquet"])
    assert cli.interrupted_line(args, []) == "datagen eval: interrupted; nothing written to e.parquet; rerun the same command"
    assert cli.interrupted_line(None, ["synth", "--num", "2"]) == ("datagen synth: interrupted; nothing was done; "
                                                                  "rerun the command")


def test_a_closed_stdout_is_not_a_traceback():
    # `true` exits before the command prints: its output goes to a closed pipe (`datagen tasks | head`)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(["bash", "-c", f"{sys.executable} -m datagen.cli tasks | true; exit ${{PIPESTATUS[0]}}"],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert (proc.returncode, proc.stderr) == (141, "")


def _group_alive(pgid: int) -> list[str]:
    """Processes of group ``pgid`` that still run (zombies excluded: reaped by init), as 'pid name'."""
    out = []
    for d in Path("/proc").iterdir():
        try:
            stat = (d / "stat").read_text()
        except (OSError, NotADirectoryError):
            continue
        name, rest = stat[stat.index("(") + 1: stat.rindex(")")], stat[stat.rindex(")") + 2:].split()
        if int(rest[2]) == pgid and rest[0] != "Z":
            out.append(f"{d.name} {name}")
    return out


def _children(pid: int) -> int:
    return sum(1 for d in Path("/proc").glob("[0-9]*") if _ppid(d) == pid)


def _ppid(d: Path) -> int:
    try:
        stat = (d / "stat").read_text()
    except OSError:
        return -1
    return int(stat[stat.rindex(")") + 2:].split()[1])


def interrupt(args: list[str], ready, settle_s: float = 0.2, timeout_s: float = 180) -> tuple[int, str]:
    """Run ``datagen ARGS`` in its own process group; once ``ready(pid)`` holds (then ``settle_s``
    later) send SIGINT to the group, as Ctrl-C does. Returns (exit code, stderr); asserts that the
    command was still running when interrupted and that no process of its group outlives it."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    # default SIGINT disposition even when this test runs in a shell that ignores it
    proc = subprocess.Popen([sys.executable, "-m", "datagen.cli", *args], cwd=REPO, env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        t0 = time.monotonic()
        while not ready(proc.pid):
            assert proc.poll() is None, f"the command ended before it was interrupted: {proc.communicate()}"
            assert time.monotonic() - t0 < timeout_s, "the command never got ready to be interrupted"
            time.sleep(0.05)
        time.sleep(settle_s)
        assert proc.poll() is None, f"the command ended before it was interrupted: {proc.communicate()}"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        time.sleep(0.5)
        assert _group_alive(proc.pid) == []
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return proc.returncode, err


def _check(code: int, err: str, line: str) -> None:
    assert code == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.strip().splitlines()[-1] == line


@pytest.fixture(scope="module")
def meshes(tmp_path_factory) -> Path:
    """A box (CoACD: about a second) and the procedural vase (several seconds), as OBJ files."""
    from datagen.objects.sources import iter_source

    root = tmp_path_factory.mktemp("meshes")
    trimesh.creation.box((1.0, 0.7, 0.5)).export(root / "a_box.obj")
    (root / "b_vase.obj").write_bytes(list(iter_source("procedural:0", 9))[8].read_bytes())
    return root


def _processing(cache: Path, finished: int = 0):
    """Ready once ``finished`` objects are in ``cache`` and CoACD runs on the next one."""
    return lambda pid: (len(list(cache.glob("objects/*/*/meta.json"))) >= finished
                        and bool(list(cache.glob("tmp/*/normalized.obj"))))


def _complete_entries(cache: Path) -> bool:
    return all((e / "meta.json").is_file() for e in cache.glob("objects/*/*"))


@pytest.mark.slow
def test_ctrl_c_in_prepare_keeps_the_finished_objects(tmp_path, meshes, capsys):
    manifest, cache, results = tmp_path / "m.jsonl", tmp_path / "cache", tmp_path / "results.jsonl"
    assert cli.main(["manifest", "build", "--source", f"dir:{meshes}", "--out", str(manifest)]) == 0
    args = ["prepare", "--manifest", str(manifest), "--cache", str(cache), "--results", str(results)]
    code, err = interrupt(args, _processing(cache, finished=1))  # the box done, the vase in CoACD
    _check(code, err, "datagen prepare: interrupted; the objects finished so far are in the cache and are not "
                      "processed again (no --results file was written); rerun the same command to process the rest")
    assert not results.exists() and _complete_entries(cache)
    capsys.readouterr()
    assert cli.main([*args, "--limit", "1"]) == 0
    assert "1 objects: 1 ok, 1 cache hits" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.parametrize("stage", ["processing", "synthesis"])
def test_ctrl_c_in_synth_writes_nothing(stage, tmp_path, meshes):
    cache, out = tmp_path / "cache", tmp_path / "out" / "g.parquet"
    mesh = meshes / ("b_vase.obj" if stage == "processing" else "a_box.obj")
    args = ["synth", "--object", str(mesh), "--cache", str(cache), "--num", "2", "--seeds", "1",
            "--iters", "1000000", "--out", str(out)]
    ready = _processing(cache) if stage == "processing" else (
        lambda pid: bool(list(cache.glob("objects/*/*/meta.json"))))
    code, err = interrupt(args, ready, settle_s=0.2 if stage == "processing" else 3.0)
    _check(code, err, f"datagen synth: interrupted; nothing written to {out}; rerun the same command (a processed "
                      "object stays in the cache)")
    assert not out.exists() and not (out.parent.exists() and list(out.parent.iterdir()))
    assert _complete_entries(cache)


@pytest.mark.slow
@pytest.mark.mujoco
def test_ctrl_c_in_eval_writes_nothing(tmp_path, meshes):
    cache, grasps, out = tmp_path / "cache", tmp_path / "g.parquet", tmp_path / "e.parquet"
    assert cli.main(["synth", "--object", str(meshes / "a_box.obj"), "--cache", str(cache), "--num", "4", "--seeds",
                     "1", "--iters", "150", "--out", str(grasps)]) == 0
    many = tmp_path / "g200.parquet"  # minutes of simulation
    pq.write_table(pa.concat_tables([pq.read_table(grasps)] * 50), many)
    code, err = interrupt(["eval", str(many), "--out", str(out), "--workers", "2"],
                          lambda pid: _children(pid) >= 2, settle_s=2.0)  # both workers simulating
    _check(code, err, f"datagen eval: interrupted; nothing written to {out}; rerun the same command")
    # hands/: the hand the synth table's rows name, pinned beside it by synth (datagen.hands.pin)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache", "g.parquet", "g200.parquet", "hands"]
