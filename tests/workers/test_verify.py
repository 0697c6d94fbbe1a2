"""A job that verifies itself: the ledger records each file's size, rows and sha256; a flipped bit,
a deleted, truncated or otherwise damaged shard, an empty ledger entry or a truncated job.json is
found (`datagen status` cheaply, `datagen verify` to the hash), refused by the readers naming the
file, and redone by a rerun with the same rows."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from datagen import cli
from datagen.io import ShardError, read_job
from workers.job import JobDir, JobError
from workers.status import job_status

from .conftest import comparable_rows, tiny_config
from .test_shard import run_all


@pytest.fixture(scope="module")
def pristine(tmp_path_factory, mesh_source, cache_dir):
    """A finished tiny job: shards 0 and 1 have rows (a box, a ball), shard 2 only a failure."""
    job = run_all(tmp_path_factory.mktemp("verify") / "job", tiny_config(mesh_source), cache_dir)
    return job.path, comparable_rows(job.path)


@pytest.fixture
def job(pristine, tmp_path) -> JobDir:
    shutil.copytree(pristine[0], tmp_path / "job")
    return JobDir(tmp_path / "job")


def flip_bit_in(path: Path, column: str) -> int:
    """Flip one bit near the end of ``column``'s (last) data page; returns the byte offset."""
    md = pq.read_metadata(path)
    k = next(i for i in range(md.num_columns) if md.schema.column(i).path.split(".")[0] == column)
    chunk = md.row_group(0).column(k)
    start = chunk.dictionary_page_offset if chunk.has_dictionary_page else chunk.data_page_offset
    offset = start + chunk.total_compressed_size - 8  # in the last page's values
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x04
    path.write_bytes(bytes(data))
    return offset


def test_the_ledger_records_every_file_it_vouches_for(job):
    entry = json.loads(job.ledger_path(0).read_text())
    rec = entry["files"]["shards/part-00000.parquet"]
    assert rec["bytes"] == job.shard_path(0).stat().st_size
    assert rec["rows"] == pq.read_metadata(job.shard_path(0)).num_rows
    assert rec["rows"] == entry["grasps"] == 2
    assert sorted(json.loads(job.ledger_path(2).read_text())["files"]) == ["failures/part-00002.parquet"]  # no rows


def test_a_flipped_bit_is_refused_and_verify_names_it(job, capsys):
    before = pq.read_table(job.shard_path(0))["grasp_qpos"].to_pylist()
    flip_bit_in(job.shard_path(0), "grasp_qpos")
    # what a reader without page checksums gets: other numbers, silently
    assert pq.read_table(job.shard_path(0), page_checksum_verification=False)["grasp_qpos"].to_pylist() != before
    with pytest.raises(ShardError, match=r"shards/part-00000.parquet: damaged: .*CRC checksum verification failed.*"
                                         r"rerun the job \(`datagen run --resume --out "):
        read_job(job.path)
    assert cli.main(["verify", str(job.path)]) == 1
    out = capsys.readouterr().out
    assert "shard 0: shards/part-00000.parquet: sha256 " in out and "!= the ledger's" in out, out
    assert f"repair: datagen run --resume --out {job.path}" in out
    assert cli.main(["report", str(job.path), "--renders", "0"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "part-00000.parquet: damaged" in err, err


def test_missing_truncated_and_unreadable_entries_are_not_done(job, capsys):
    job.shard_path(1).unlink()                                   # deleted, its ledger entry kept
    data = job.shard_failures_path(0).read_bytes()
    job.shard_failures_path(0).write_bytes(data[: len(data) // 2])  # truncated
    job.ledger_path(2).write_text("")                            # an empty ledger entry
    s = job_status(job.path)
    assert not s["complete"] and s["shards_done"] == 0 and s["grasps"] == 0
    assert s["damaged"] == {0: f"failures/part-00000.parquet: truncated: {len(data) // 2} bytes, the ledger "
                               f"recorded {len(data)}",
                            1: s["damaged"][1], 2: "ledger/part-00002.json: the ledger entry is empty"}
    assert s["damaged"][1].startswith("shards/part-00001.parquet: missing (the ledger lists 2 rows")
    assert cli.main(["status", str(job.path)]) == 0
    out = capsys.readouterr().out
    assert "shard 1 is not counted: shards/part-00001.parquet: missing" in out
    assert f"datagen run --resume --out {job.path}" in out
    with pytest.raises(ShardError, match=r"failures/part-00000.parquet: truncated: .*; and 2 more shard"):
        read_job(job.path)


def test_a_damaged_page_header_names_the_file(job, capsys):
    path = job.shard_path(1)
    md = pq.read_metadata(path)
    data = bytearray(path.read_bytes())
    start = md.row_group(0).column(0).data_page_offset
    data[start:start + 4] = b"\xff\xff\xff\xff"  # the page header's first bytes
    path.write_bytes(bytes(data))
    with pytest.raises(ShardError, match=r"part-00001.parquet: damaged: "):
        read_job(job.path)
    assert cli.main(["report", str(job.path), "--renders", "0"]) == 2
    assert "part-00001.parquet: damaged" in capsys.readouterr().err


def test_a_truncated_job_json_is_named_and_rewritten_by_a_matching_config(job, mesh_source, capsys):
    doc = (job.path / "job.json").read_text()
    (job.path / "job.json").write_text(doc[: len(doc) // 3])
    assert cli.main(["status", str(job.path)]) == 2
    err = capsys.readouterr().err
    assert f"{job.path}/job.json: the job file is not valid JSON (" in err, err
    cfg = tiny_config(mesh_source)
    assert f"its shards record config hash {cfg.hash()[:12]}" in err and "Expecting value" not in err.split("(")[0]
    with pytest.raises(JobError, match="job.json: the job file is not valid JSON"):
        JobDir(job.path).init(tiny_config(mesh_source, seed=9))  # not what the shards record: refused
    assert JobDir(job.path).init(cfg) is True  # resumes, job.json written again
    assert json.loads((job.path / "job.json").read_text())["config_hash"] == cfg.hash()
    (job.path / "job.json").write_text("")
    assert cli.main(["verify", str(job.path)]) == 2
    assert "job.json: the job file is empty" in capsys.readouterr().err


def test_a_changed_manifest_is_named_by_verify_and_built_again_on_resume(job, mesh_source, capsys):
    from workers.setup import prepare_manifest

    text = job.manifest_path.read_text()
    record = json.loads((job.path / "ledger" / "manifest.json").read_text())
    assert record["bytes"] == len(text.encode()) and record["lines"] == 3  # three objects
    edited = text.replace('"split": "train"', '"split": "test"', 1)
    assert edited != text and len(edited) == len(text) - 1
    job.manifest_path.write_text(edited + " ")  # the same size, another object split: silent before
    assert cli.main(["verify", str(job.path)]) == 1
    out = capsys.readouterr().out
    assert "  manifest.jsonl: sha256 " in out and "its bytes changed" in out, out
    assert "builds the manifest again from the job's source" in out
    entries = prepare_manifest(job, tiny_config(mesh_source))  # what a resume does
    assert "manifest.jsonl sha256 " in capsys.readouterr().err
    assert job.manifest_path.read_text() == text and [e.id for e in entries] == ["a_box.obj", "b_ball.obj",
                                                                                "c_bad.obj"]
    assert cli.main(["verify", str(job.path)]) == 0
    job.manifest_path.unlink()  # deleted: built again too
    prepare_manifest(job, tiny_config(mesh_source))
    assert job.manifest_path.read_text() == text
    job.manifest_path.write_text(edited + " ")
    with pytest.raises(JobError, match=r"manifest.jsonl sha256 .*its bytes changed, and the job's source does not "
                                       r"give it again: .*restore it from a copy"):
        prepare_manifest(job, tiny_config(mesh_source, count=2))  # a source that now holds other objects


@pytest.mark.ray
@pytest.mark.slow
def test_a_rerun_redoes_exactly_the_damaged_shards(job, pristine, mesh_source, cache_dir):
    from workers.run import run_job

    flip_bit_in(job.shard_path(0), "grasp_qpos")
    job.shard_path(1).unlink()
    job.ledger_path(2).write_text("{")
    (job.objects_dir / ".half.123.tmp").mkdir()  # left by a killed run
    said = []
    status = run_job(tiny_config(mesh_source), job.path, num_cpus=2, cache=cache_dir, progress=False,
                     log=said.append)
    assert said[:4] == [
        "removed objects/.half.123.tmp, left by an interrupted run",
        said[1], "shard 1: " + said[2].split(": ", 1)[1], "shard 2: ledger/part-00002.json: the ledger entry is not "
        "valid JSON (Expecting property name enclosed in double quotes at line 1 column 2); redoing it"]
    assert said[1].startswith("shard 0: shards/part-00000.parquet: sha256 ") and said[1].endswith("; redoing it")
    assert said[2].startswith("shard 1: shards/part-00001.parquet: missing (the ledger lists 2 rows")
    assert "0 done, 3 to run" in said[4]
    assert status["complete"] and not status["damaged"]
    assert comparable_rows(job.path) == pristine[1]  # the same seeds: the same rows
    observed = sorted((pristine[0] / "observations").glob("*.parquet"))
    assert [p.name for p in observed] == ["part-00000.parquet", "part-00001.parquet"]
    for p in observed:  # and the same observations (depth images included)
        assert pq.read_table(job.path / "observations" / p.name).equals(pq.read_table(p)), p.name
    assert cli.main(["verify", str(job.path)]) == 0


@pytest.mark.ray
@pytest.mark.slow
def test_a_full_disk_is_one_line_and_the_rerun_finishes(tmp_path, pristine, mesh_source, cache_dir, capsys):
    import os
    import re
    import subprocess

    import yaml

    from .test_bad_input_table import _matches, table_rows

    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    small = tmp_path / "small"
    small.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=128k", "tmpfs", str(small)]).returncode:
        pytest.skip("cannot mount a tmpfs here")
    try:
        out = small / ("job_" + "x" * 40)  # a long path: Ray's temp dir goes to /tmp, not onto the small disk
        (tmp_path / "job.yaml").write_text(yaml.safe_dump(tiny_config(mesh_source).to_dict()))
        args = ["run", "--out", str(out), "--config", str(tmp_path / "job.yaml"), "--num-cpus", "1", "--cache",
                cache_dir, "--no-progress"]
        assert cli.main(args) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"datagen run: error: cannot write the ") and str(out) in err[0]
        assert ": No space left on device (free space on the file system holding " in err[0], err
        cell = table_rows()["the disk under `--out` fills up"]  # the README's row says so
        assert cell.startswith("exit 1: ") and _matches(re.findall(r"`([^`]*)`", cell)[-1], err[0])
        found = JobDir(out).audit(deep=True)
        assert not found.problems and len(found.finished) < 3  # no half file counted as done
        subprocess.run(["mount", "-o", "remount,size=8m", str(small)], check=True)
        assert cli.main(args) == 0
        assert not list(out.rglob("*.tmp"))  # a killed shard's half-copied object included
        assert comparable_rows(out) == pristine[1]
    finally:
        subprocess.run(["umount", "-l", str(small)], check=False)


def test_report_on_a_read_only_job_is_one_line(job, tmp_path, capsys):
    import os
    import subprocess

    ro = tmp_path / "ro"
    if os.geteuid() == 0:  # root writes through permissions: a read-only bind mount instead
        ro.mkdir()
        if subprocess.run(["mount", "--bind", str(job.path), str(ro)]).returncode or subprocess.run(
                ["mount", "-o", "remount,bind,ro", str(ro)]).returncode:
            subprocess.run(["umount", "-l", str(ro)], check=False)
            pytest.skip("cannot make a read-only bind mount here")
    else:
        ro = job.path
        ro.chmod(0o555)
    try:
        assert cli.main(["report", str(ro), "--renders", "0"]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"datagen report: error: cannot write the dataset card {ro}/README.md: the job directory is not "
                       "writable (run `datagen report` on a writable copy of the job (cp -r), or as its owner)"]
        assert cli.main(["status", str(ro)]) == 0  # reading a read-only job is fine
    finally:
        if ro != job.path:
            subprocess.run(["umount", "-l", str(ro)], check=False)
        else:
            ro.chmod(0o755)
