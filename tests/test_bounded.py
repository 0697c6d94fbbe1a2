"""Bounded reads of a user's paths (`datagen._bounded`): a device, a FIFO, a socket or a folder is
refused before a byte is read, at once; a file over its cap is refused from its size; memory stays
bounded. And every command that takes such a path says so in one line (exit 2), before its heavy
imports, under an address-space limit that turns a reader that reads on into a MemoryError
instead of a host out of memory."""

from __future__ import annotations

import os
import resource
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from datagen import _bounded
from datagen._bounded import InputError

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def specials(tmp_path):
    """name -> a path that is not a regular file."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(tmp_path / "sock"))
    yield {"/dev/zero": Path("/dev/zero"), "a FIFO": fifo, "a socket": tmp_path / "sock", "a folder": tmp_path}
    sock.close()


KINDS = {"/dev/zero": "a character device", "a FIFO": "a FIFO (named pipe)", "a socket": "a socket",
         "a folder": "a directory"}


@pytest.mark.parametrize("reader", ["read_bytes", "read_text", "sha256_file", "iter_lines", "read_json"])
def test_special_files_are_refused_at_once(specials, reader):
    calls = {"read_bytes": lambda p: _bounded.read_bytes(p, 1 << 20, "thing"),
             "read_text": lambda p: _bounded.read_text(p, 1 << 20, "thing"),
             "sha256_file": lambda p: _bounded.sha256_file(p, 1 << 20, "thing"),
             "iter_lines": lambda p: list(_bounded.iter_lines(p, 1 << 20, 1 << 10, "thing")),
             "read_json": lambda p: _bounded.read_json(p, "thing")}
    for name, path in specials.items():
        t0 = time.perf_counter()
        with pytest.raises(InputError) as info:
            calls[reader](path)
        assert time.perf_counter() - t0 < 1.0  # a FIFO without a writer is not waited for
        assert str(info.value) == f"{path}: the thing is {KINDS[name]}, not a regular file"
        assert info.value.reason == _bounded.NOT_REGULAR


def test_caps_missing_files_and_text(tmp_path):
    big = tmp_path / "big"
    big.write_bytes(b"x" * 2049)
    with pytest.raises(InputError, match=r"big: the mesh is 2.001 KiB, over its limit of 2 KiB") as info:
        _bounded.read_bytes(big, 2048, "mesh")
    assert info.value.reason == _bounded.TOO_LARGE
    assert _bounded.sha256_file(big, 4096, "mesh")[1] == 2049
    sparse = tmp_path / "sparse.obj"  # 3 GiB that take no disk: refused from its size, unread
    with open(sparse, "wb") as fh:
        fh.truncate(3 << 30)
    with pytest.raises(InputError, match="the mesh is 3 GiB, over its limit of 256 MiB"):
        _bounded.sha256_file(sparse, 256 << 20, "mesh")
    with pytest.raises(InputError, match="the config file does not exist") as info:
        _bounded.read_text(tmp_path / "nope.yaml", 100, "config")
    assert info.value.reason == _bounded.NOT_FOUND
    (tmp_path / "latin1").write_bytes(b"caf\xe9")
    with pytest.raises(InputError, match="not UTF-8 text"):
        _bounded.read_text(tmp_path / "latin1", 100, "config")
    (tmp_path / "lines").write_text("a\n" + "b" * 50 + "\nc\n")
    with pytest.raises(InputError, match=r"lines:2: line longer than 16 bytes"):
        list(_bounded.iter_lines(tmp_path / "lines", 1000, 16, "manifest"))
    assert [t for _, t in _bounded.iter_lines(tmp_path / "lines", 1000, 64, "manifest")] == ["a", "b" * 50, "c"]
    for text, why in (("", "is empty"), ('{"a": 1', "is not valid JSON")):
        (tmp_path / "j.json").write_text(text)
        with pytest.raises(InputError, match=f"j.json: the ledger entry {why}"):
            _bounded.read_json(tmp_path / "j.json", "ledger entry")


def _cli(args: list[str], timeout_s: float = 240) -> tuple[int, str, set[str]]:
    """(exit code, stderr, top-level modules imported) of ``datagen ARGS`` in a child limited to
    3 GiB of address space (torch and Ray import within it): a reader that reads a device on fails
    with a MemoryError there instead of taking the machine's memory. The modules come from
    Python's own ``-X importtime`` report, which is kept out of the stderr returned."""
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    proc = subprocess.run([sys.executable, "-X", "importtime", "-m", "datagen.cli", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=timeout_s,
                          preexec_fn=limit)  # a FIFO that hangs fails the test, not the suite
    lines = proc.stderr.splitlines()
    report = [ln for ln in lines if ln.startswith("import time:")]
    modules = {ln.rsplit("|", 1)[-1].strip().split(".")[0] for ln in report[1:]}
    return proc.returncode, "\n".join(ln for ln in lines if not ln.startswith("import time:")), modules


@pytest.mark.parametrize("what", ["/dev/zero", "a FIFO"])
@pytest.mark.parametrize("command", ["run --manifest", "run --config", "manifest check", "prepare --manifest"])
def test_commands_refuse_devices_and_fifos_in_one_line(tmp_path, specials, what, command, capsys):
    from datagen import cli

    path = specials[what]
    args = command.split() + [str(path)]
    if command.startswith("run"):
        args += ["--out", str(tmp_path / "job"), "--no-progress"]
    t0 = time.perf_counter()
    code = cli.main(args)
    err = capsys.readouterr().err
    kind = "manifest" if "manifest" in command else "job config"
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and f"{path}" in err and f"the {kind} is {KINDS[what]}" in err, err
    assert time.perf_counter() - t0 < 60  # a FIFO is not waited for (a wait never ends; the first call also imports the command)
    assert not (tmp_path / "job").exists()


@pytest.mark.parametrize("what,args", [("/dev/zero", ["run", "--manifest"]), ("a FIFO", ["run", "--config"]),
                                       ("a FIFO", ["manifest", "check"]), ("/dev/zero", ["prepare", "--manifest"])])
def test_a_fresh_process_refuses_them_at_once_in_little_memory(tmp_path, specials, what, args):
    path = specials[what]
    extra = ["--out", str(tmp_path / "job"), "--no-progress"] if args[0] == "run" else []
    code, err, modules = _cli([*args, str(path), *extra])
    assert code == 2 and len(err.strip().splitlines()) == 1 and KINDS[what] in err, err
    assert "datagen" in modules and not modules & {"torch", "ray", "mujoco", "trimesh", "pyarrow"}, \
        sorted(modules)  # refused before the command's imports: ~0.2 s, ~20 MiB
    assert not (tmp_path / "job").exists()
