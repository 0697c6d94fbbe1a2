"""Processing in isolation (`datagen.objects.isolate`, used by `datagen prepare` and the job
workers): an object whose processing hangs or kills its process is a failure naming it and the
reason, and the other objects of the batch are processed all the same."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import trimesh

from datagen.objects.isolate import process_isolated
from datagen.objects.manifest import build_manifest
from datagen.objects.prepare import prepare, summarize
from datagen.objects.process import process_object


def misbehaving_step(ref, cfg, root, expected_sha256):
    """`process_object`, except that ``hang*`` objects never finish and ``crash*`` ones kill their
    process (what a native CoACD failure looks like). Module level: the child imports it."""
    if ref.object_id.startswith("hang"):
        time.sleep(3600)
    if ref.object_id.startswith("crash"):
        os._exit(3)
    return process_object(ref, cfg, root, expected_sha256)


def boxes(tmp_path, names):
    """Manifest entries of one box per name (sizes differ, so the bytes do), in name order."""
    src = tmp_path / "meshes"
    src.mkdir()
    for i, name in enumerate(names):
        trimesh.creation.box((1.0, 0.7, 0.5 + 0.1 * i)).export(src / f"{name}.obj")
    return build_manifest(f"dir:{src}", None, (0.08,), 0.0)


@pytest.mark.slow
def test_a_hanging_or_crashing_object_costs_only_itself(tmp_path, fast_cfg):
    entries = boxes(tmp_path, ("a_cached", "crash", "hang", "z_fresh"))
    assert [e.id for e in entries] == ["a_cached.obj", "crash.obj", "hang.obj", "z_fresh.obj"]
    cache = tmp_path / "cache"
    assert process_object(entries[0].ref(), fast_cfg, cache).ok  # a cache hit starts no process
    t0 = time.monotonic()
    got = prepare(entries, fast_cfg, cache, workers=4, progress=False, timeout_s=20, step=misbehaving_step)
    assert time.monotonic() - t0 < 60  # the hanging one was killed, not waited for
    assert [(r["id"], r["status"], r["reason"], r["cache_hit"]) for r in got] == [
        ("a_cached.obj", "ok", "", True), ("crash.obj", "failed", "crashed", False),
        ("hang.obj", "failed", "timeout", False), ("z_fresh.obj", "ok", "", False)]
    assert got[1]["message"] == "crash.obj: the processing process died (exit code 3)"
    assert got[2]["message"].startswith("hang.obj: processing exceeded 20 s and was killed (raise")
    assert got[3]["pieces"] >= 1 and os.path.isfile(os.path.join(got[3]["entry"], "meta.json"))
    assert summarize(got).splitlines() == [
        "4 objects: 2 ok, 1 cache hits; failures: crashed: 1, timeout: 1",
        "  crash.obj: the processing process died (exit code 3)", "  " + got[2]["message"],
        "every object's status, one JSON line each: rerun with --results FILE (cache hits are cheap)"]
    assert summarize(got, "r.jsonl").splitlines()[-1] == "every object's status: r.jsonl"


def test_a_time_limit_must_be_positive(tmp_path):
    with pytest.raises(ValueError, match="time limit must be > 0"):
        prepare([], None, tmp_path, progress=False, timeout_s=0)


def pid_step(ref, cfg, root, expected_sha256):
    """`process_object` that notes the process it ran in beside the cache (``crash*`` objects kill it)."""
    if ref.object_id.startswith("crash"):
        os._exit(3)
    with open(Path(root).parent / "pids.txt", "a") as fh:
        fh.write(f"{os.getpid()}\n")
    return process_object(ref, cfg, root, expected_sha256)


@pytest.mark.slow
def test_one_worker_serves_object_after_object_and_a_crash_costs_only_its_worker(tmp_path, fast_cfg):
    entries = boxes(tmp_path, ("a", "b", "crash", "d"))
    got = [process_isolated(e, fast_cfg, tmp_path / "cache", 60, step=pid_step) for e in entries]
    assert [(g.status, g.reason) for g in got] == [("ok", ""), ("ok", ""), ("failed", "crashed"), ("ok", "")]
    pids = [int(x) for x in (tmp_path / "pids.txt").read_text().split()]
    assert pids[0] == pids[1] != os.getpid()  # the same worker, not this process
    assert pids[2] not in (pids[0], os.getpid())  # the crashed worker was replaced
    assert got[2].message == "crash.obj: the processing process died (exit code 3)"


@pytest.mark.slow
def test_a_script_without_a_main_guard_runs_once(tmp_path, fast_cfg):
    """The workers never import the caller's main module (multiprocessing's spawn would run this
    script again in every child, which then processed its objects again, recursively)."""
    src = tmp_path / "meshes"
    src.mkdir()
    for name in ("a", "b"):
        trimesh.creation.icosphere(subdivisions=1).export(src / f"{name}.obj")
    script = tmp_path / "script.py"
    script.write_text(
        "import dataclasses\n"
        "from datagen.objects.isolate import process_isolated\n"
        "from datagen.objects.manifest import build_manifest\n"
        "from datagen.objects.config import ProcessConfig\n"
        f"open({str(tmp_path / 'runs.txt')!r}, 'a').write('run\\n')\n"
        f"cfg = ProcessConfig(**{dataclasses.asdict(fast_cfg)!r})\n"
        f"for e in build_manifest('dir:{src}', None, (0.08,), 0.0):\n"
        f"    print(process_isolated(e, cfg, {str(tmp_path / 'cache')!r}, 60).status)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[2])] + sys.path)}
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["ok", "ok"]
    assert (tmp_path / "runs.txt").read_text() == "run\n"
