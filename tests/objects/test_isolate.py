"""Processing in isolation (`datagen.objects.isolate`, used by `datagen prepare` and the job
workers): an object whose processing hangs or kills its process is a failure naming it and the
reason, and the other objects of the batch are processed all the same."""

from __future__ import annotations

import os
import time

import pytest
import trimesh

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


@pytest.mark.slow
def test_a_hanging_or_crashing_object_costs_only_itself(tmp_path, fast_cfg):
    src = tmp_path / "meshes"
    src.mkdir()
    for i, name in enumerate(("a_cached", "crash", "hang", "z_fresh")):
        trimesh.creation.box((1.0, 0.7, 0.5 + 0.1 * i)).export(src / f"{name}.obj")
    entries = build_manifest(f"dir:{src}", None, (0.08,), 0.0)
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
    assert summarize(got) == "4 objects: 2 ok, 1 cache hits; failures: crashed: 1, timeout: 1"


def test_a_time_limit_must_be_positive(tmp_path):
    with pytest.raises(ValueError, match="time limit must be > 0"):
        prepare([], None, tmp_path, progress=False, timeout_s=0)
