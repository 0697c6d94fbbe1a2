import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from datagen import cli
from datagen.objects import layout
from datagen.objects.cache import clean_stale_temp


@pytest.mark.slow
def test_manifest_build_then_prepare_twice(tmp_path, capsys, fast_cfg):
    out = tmp_path / "manifests" / "tiny.jsonl"
    assert cli.main(["manifest", "build", "--source", "procedural:1", "--count", "3",
                     "--out", str(out)]) == 0
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert [x["id"] for x in lines] == ["proc-s1-000000", "proc-s1-000001", "proc-s1-000002"]
    cfg = tmp_path / "fast.yaml"
    cfg.write_text(yaml.safe_dump({"process": fast_cfg.to_dict()}))  # the config file's processing part
    results = tmp_path / "results.jsonl"
    args = ["prepare", "--manifest", str(out), "--config", str(cfg), "--cache",
            str(tmp_path / "cache"), "--results", str(results)]
    assert cli.main(args) == 0
    first = [json.loads(x) for x in results.read_text().splitlines()]
    assert [r["status"] for r in first] == ["ok"] * 3 and not any(r["cache_hit"] for r in first)
    assert cli.main(args) == 0
    assert "3 ok, 3 cache hits" in capsys.readouterr().out
    # the process-pool path gives the same answers, in manifest order
    from datagen.objects.prepare import prepare

    pooled = prepare(out, fast_cfg, tmp_path / "cache", workers=2, progress=False)
    assert [(r["id"], r["entry"]) for r in pooled] == [(r["id"], r["entry"]) for r in first]
    assert all(r["cache_hit"] for r in pooled)


def test_bad_manifest_is_a_clean_error(tmp_path, capsys):
    bad = tmp_path / "bad.jsonl"
    bad.write_text("{not json\n")
    assert cli.main(["manifest", "check", str(bad)]) == 2
    assert "malformed_line" in capsys.readouterr().err


def test_bad_config_names_the_field(tmp_path, capsys):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("process: {coacd_threshold: 0, wrong_name: 1}\n")
    (tmp_path / "m.jsonl").write_text("")
    assert cli.main(["prepare", "--manifest", str(tmp_path / "m.jsonl"), "--config", str(cfg)]) == 2
    assert "coacd_threshold" in capsys.readouterr().err


def test_skipped_files_are_warnings_on_stderr(tmp_path, capsys, box_obj):
    """The library logs a skipped file (logger datagen.objects.manifest); the CLI's one handler
    prints it on stderr, and the manifest holds the other objects."""
    (tmp_path / "src" / "x.obj").mkdir(parents=True)  # a folder named like a mesh
    (tmp_path / "src" / "y.obj").write_bytes(box_obj)
    out = tmp_path / "m.jsonl"
    assert cli.main(["manifest", "build", "--source", f"dir:{tmp_path / 'src'}", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "datagen: warning: skipped x.obj: not_a_regular_file" in err, err
    assert [json.loads(x)["id"] for x in out.read_text().splitlines()] == ["y.obj"]
    assert cli.main(["manifest", "build", "--source", f"dir:{tmp_path / 'src'}", "--out", str(out)]) == 0
    assert capsys.readouterr().err.count("skipped x.obj") == 1  # main() again: still one handler


def register_hello(sub):
    p = sub.add_parser("hello")
    p.set_defaults(func=lambda args: print("hi") or 0)


def test_other_packages_register_subcommands(monkeypatch, capsys):
    monkeypatch.setitem(cli.REGISTRARS, "hello", f"{__name__}:register_hello")
    assert cli.main(["hello"]) == 0
    assert capsys.readouterr().out == "hi\n"


@pytest.mark.slow
def test_killed_process_leaves_no_half_entry(tmp_path):
    """SIGKILL in the middle of CoACD: no entry appears; the temp dir is cleaned later."""
    code = ("from datagen.objects.sources import iter_source\n"
            "from datagen.objects.process import process_object\n"
            "ref = list(iter_source('procedural:0', 9))[8]\n"  # a vase: seconds of CoACD
            f"process_object(ref, None, {str(tmp_path)!r})\n")
    proc = subprocess.Popen([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": os.getcwd()})
    deadline = time.time() + 60
    while not list(Path(tmp_path, "tmp").glob("*/normalized.obj")) and time.time() < deadline:
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not list(Path(tmp_path, "objects").rglob(layout.META))
    assert len(list(Path(tmp_path, "tmp").iterdir())) == 1
    assert clean_stale_temp(tmp_path, older_than_s=0) == 1
    assert not list(Path(tmp_path, "tmp").iterdir())
