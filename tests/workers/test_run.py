"""The Ray driver: a killed driver resumes without losing or duplicating rows and leaves no Ray
process behind, SIGTERM stops it as Ctrl-C does, a different config on the same directory is
refused, the local cluster listens on the loopback interface only. (A lost worker node:
test_cluster.py.)"""

from __future__ import annotations

import hashlib
import ipaddress
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from workers.job import JobDir, JobError
from workers.cluster import start_local_ray, stop_local_ray
from workers.run import run_job

from .conftest import comparable_rows, tiny_config
from .test_shard import run_all

pytestmark = [pytest.mark.ray, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def reference(tmp_path_factory, mesh_source, cache_dir):
    """The rows of an uninterrupted run (shards run in this process, no Ray)."""
    return comparable_rows(run_all(tmp_path_factory.mktemp("ref") / "job", tiny_config(mesh_source), cache_dir).path)


def _wait_for(pred, timeout_s: float, what: str):
    t0 = time.monotonic()
    while not pred():
        assert time.monotonic() - t0 < timeout_s, f"timed out waiting for {what}"
        time.sleep(0.2)


def _run_command(tmp_path, mesh_source, cache_dir):
    """The tiny job's config, its directory and the `datagen run` command line (one CPU)."""
    cfg = tiny_config(mesh_source)
    out = tmp_path / "job"
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(cfg.to_dict()))
    cmd = [sys.executable, "-m", "datagen.cli", "run", "--out", str(out), "--config", str(tmp_path / "job.yaml"),
           "--num-cpus", "1", "--cache", cache_dir, "--no-progress"]
    return cfg, out, cmd


def test_sigkilled_driver_resumes_to_the_same_rows(tmp_path, mesh_source, cache_dir, reference):
    cfg, out, cmd = _run_command(tmp_path, mesh_source, cache_dir)
    proc = subprocess.Popen(cmd, cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        _wait_for(lambda: len(JobDir(out).finished()) >= 1 if (out / "ledger").is_dir() else False, 150,
                  "the first finished shard")
        sessions = _ray_sessions(out)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        try:  # the driver's local Ray processes share its session: end them too
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    _assert_no_ray_process_left(sessions, within_s=20)  # the reaper ends them: Ray alone takes ~90 s
    done_before = set(JobDir(out).finished())
    if len(done_before) == 3:  # every shard finished before the kill landed (the poll is not a barrier):
        # emulate a kill right after the first shard; shards are idempotent, the resume redoes the others
        for i in sorted(done_before)[1:]:
            JobDir(out).ledger_path(i).unlink()
        done_before = set(JobDir(out).finished())
    assert 1 <= len(done_before) < 3, done_before
    status = run_job(cfg, out, num_cpus=2, cache=cache_dir, progress=False, log=lambda *a: None)
    assert status["complete"] and status["shards_done"] == 3
    rows = comparable_rows(out)
    assert len({r["grasp_id"] for r in rows}) == len(rows)  # no duplicates
    assert rows == reference  # none lost, same values
    assert status["failures"] == {"process:" + status_reason(out): 1}


def test_ctrl_c_abandons_running_shards_cleanly(tmp_path, mesh_source, cache_dir, reference):
    cfg, out, cmd = _run_command(tmp_path, mesh_source, cache_dir)
    # SIGINT as a terminal's Ctrl-C sends it: to the whole process group (default disposition, even
    # when this test runs in a background shell that ignores SIGINT)
    proc = subprocess.Popen(cmd, cwd=REPO, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_for(lambda: (out / "progress").is_dir() and any((out / "progress").iterdir()), 150, "a running shard")
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=90)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "datagen run: interrupted; rerun the same command to resume"
    assert "Traceback" not in err
    status = run_job(cfg, out, num_cpus=2, cache=cache_dir, progress=False, log=lambda *a: None)
    assert status["complete"] and comparable_rows(out) == reference


def _ray_sessions(out: Path) -> list[Path]:
    """Session directories of the local clusters a job's drivers started (in its temp dir)."""
    job = JobDir(out)
    short = Path("/tmp") / f"dg-ray-{hashlib.sha256(str(job.path).encode()).hexdigest()[:10]}"
    return sorted([*(job.path / "ray").glob("session_2*"), *short.glob("session_2*")])


def _assert_no_ray_process_left(sessions: list[Path], within_s: float) -> None:
    from workers.reaper import cluster_processes

    assert sessions, "no Ray session was started"
    _wait_for(lambda: not any(cluster_processes(str(s)) for s in sessions), within_s, "the job's Ray processes to end")


def test_sigterm_stops_the_driver_as_ctrl_c_does(tmp_path, mesh_source, cache_dir):
    cfg, out, cmd = _run_command(tmp_path, mesh_source, cache_dir)
    proc = subprocess.Popen(cmd, cwd=REPO, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        _wait_for(lambda: (out / "progress").is_dir() and any((out / "progress").iterdir()), 150, "a running shard")
        sessions = _ray_sessions(out)
        os.kill(proc.pid, signal.SIGTERM)  # the driver only, as `kill PID` or a scheduler does
        _, err = proc.communicate(timeout=90)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1] == "datagen run: terminated (SIGTERM); rerun the same command to resume"
    assert "Traceback" not in err and "SIGTERM received" not in err, err  # no Python or native stack dump
    _assert_no_ray_process_left(sessions, within_s=20)


def status_reason(out: Path) -> str:
    import pyarrow.parquet as pq

    (reason,) = pq.read_table(JobDir(out).failures_path)["reason"].to_pylist()
    return reason


def test_second_run_refuses_a_different_config(tmp_path, mesh_source, cache_dir):
    out = tmp_path / "job"
    JobDir(out).init(tiny_config(mesh_source))
    with pytest.raises(JobError, match="different job"):
        run_job(tiny_config(mesh_source, seed=3), out, num_cpus=1, cache=cache_dir, progress=False)


def _descendants(root: int) -> set[int]:
    """``root`` and every process below it, from the parent pids in /proc."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:  # ended meanwhile
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])  # the name in parentheses may hold spaces
        children.setdefault(ppid, []).append(int(d.name))
    out, todo = set(), [root]
    while todo:
        pid = todo.pop()
        out.add(pid)
        todo += children.get(pid, [])
    return out


def _proc_address(hexaddr: str) -> ipaddress._BaseAddress:
    """An address of /proc/net/tcp{,6}: 32-bit words in host (little-endian) byte order."""
    raw = bytes.fromhex(hexaddr)
    return ipaddress.ip_address(b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4)))


def listening_sockets(pids: set[int]) -> list[tuple[str, ipaddress._BaseAddress, int]]:
    """(process name, address, port) of every listening TCP socket (IPv4 and IPv6) that a process
    of ``pids`` holds: its socket inodes (/proc/PID/fd) looked up in /proc/net/tcp and tcp6."""
    owner: dict[str, str] = {}
    for pid in pids:
        try:
            name = Path(f"/proc/{pid}/comm").read_text().strip()
            fds = list(Path(f"/proc/{pid}/fd").iterdir())
        except OSError:
            continue
        for fd in fds:
            try:
                link = os.readlink(fd)
            except OSError:
                continue
            if link.startswith("socket:["):
                owner[link[8:-1]] = name
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            f = line.split()
            if f[3] == "0A" and f[9] in owner:  # state 0A: LISTEN
                addr, port = f[1].split(":")
                out.append((owner[f[9]], _proc_address(addr), int(port, 16)))
    return out


def _is_loopback(addr: ipaddress._BaseAddress) -> bool:
    mapped = getattr(addr, "ipv4_mapped", None)  # ::ffff:127.0.0.1, a dual-stack socket's loopback
    return addr.is_loopback or (mapped is not None and mapped.is_loopback)


def test_local_cluster_listens_on_loopback_only(tmp_path):
    import ray

    # the scan sees a socket on every interface, and reads its address and port as the kernel has them
    with socket.socket() as probe:
        probe.bind(("0.0.0.0", 0))
        probe.listen()
        port = probe.getsockname()[1]
        assert (_proc_address("00000000"), port) in [(a, p) for _, a, p in listening_sockets({os.getpid()})]
        assert not _is_loopback(_proc_address("00000000"))
    assert _is_loopback(_proc_address("0100007F"))  # 127.0.0.1
    assert _is_loopback(_proc_address("0000000000000000FFFF00000100007F"))  # ::ffff:127.0.0.1

    job = JobDir(tmp_path / "job")
    private_tmp = start_local_ray(ray, job, 2, log=lambda *a: None)
    try:
        @ray.remote
        def pid():  # two tasks: worker processes with their gRPC servers, as a job's shards have
            time.sleep(0.5)
            return os.getpid()

        workers = set(ray.get([pid.remote(), pid.remote()]))
        ray_procs = _descendants(os.getpid())
        assert workers <= ray_procs
        sockets = listening_sockets(ray_procs)
        names = {n for n, _, _ in sockets}
        assert {"gcs_server", "raylet"} <= names and len(sockets) >= 5, sockets  # driver, GCS, raylet x2, workers
        assert [s for s in sockets if not _is_loopback(s[1])] == []
    finally:
        ray.shutdown()
        if private_tmp:
            shutil.rmtree(private_tmp, ignore_errors=True)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended but not yet reaped, counts as ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_stop_local_ray_ends_every_process_it_started(tmp_path):
    import ray

    job = JobDir(tmp_path / "job")
    before = _descendants(os.getpid())  # e.g. an earlier test's pool of isolated processing workers
    private_tmp = start_local_ray(ray, job, 1, log=lambda *a: None)
    try:
        @ray.remote
        def pid():
            return os.getpid()

        worker = ray.get(pid.remote())
        started = _descendants(os.getpid()) - before
        names = {Path(f"/proc/{p}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
                 for p in started if _alive(p)}
        assert worker in started
        assert any("autoscaler" in n and "monitor.py" in n for n in names), names  # the one it kills first
        assert any("raylet" in n for n in names) and any("gcs_server" in n for n in names), names
    finally:
        stop_local_ray(ray)
        if private_tmp:
            shutil.rmtree(private_tmp, ignore_errors=True)
    assert not ray.is_initialized()
    deadline = time.monotonic() + 10  # the workers exit once their raylet has gone
    while time.monotonic() < deadline and any(_alive(p) for p in started):
        time.sleep(0.1)
    assert [p for p in started if _alive(p)] == []
