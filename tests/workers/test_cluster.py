"""The cluster path for real: a head and a second node started with ``ray start`` on this machine
(one CPU each, on the loopback address 127.0.0.2, which Ray does not rewrite the way it rewrites
127.0.0.1 for a cluster of several nodes), a job run through ``datagen run --address``; its shards
run on both nodes, the second node is killed while it runs a shard (after another shard has
finished: mid-job), and that shard is retried on the head: the rows equal a one-node run's. The node dies as a machine would: its
raylet and every process below it (the workers) are killed at once (a worker whose raylet alone
is gone can still finish its shard before it notices)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
import trimesh
import yaml

from workers.job import JobDir
from workers.reaper import cluster_processes

from .conftest import comparable_rows, tiny_config
from .test_run import _descendants
from .test_shard import run_all

pytestmark = [pytest.mark.ray, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
HOST = "127.0.0.2"  # loopback (127.0.0.0/8), kept as given by Ray in a multi-node cluster


def _ray(*args, env) -> None:
    ray_cli = Path(sys.executable).with_name("ray")
    proc = subprocess.run([str(ray_cli), *args], env=env, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return s.getsockname()[1]


def _raylet_node_id(node_manager_port: int) -> tuple[int, str]:
    """(pid, node id) of this machine's raylet listening for its node manager on that port."""
    for d in Path("/proc").iterdir():
        try:
            args = (d / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if args and args[0].endswith(b"/raylet") and f"--node_manager_port={node_manager_port}".encode() in args:
            node = next(a for a in args if a.startswith(b"--node_id=")).split(b"=", 1)[1].decode()
            return int(d.name), node
    raise AssertionError(f"no raylet with node manager port {node_manager_port}")


def _json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def test_two_nodes_lose_nothing_when_one_dies(tmp_path, cache_dir):
    root = tmp_path / "meshes"
    root.mkdir()
    for i in range(4):  # four shards of one object: each node gets more than one
        trimesh.creation.box((1.0, 0.6 + 0.1 * i, 0.5)).export(root / f"box{i}.obj")
    cfg = tiny_config(f"dir:{root}", count=4)
    reference = comparable_rows(run_all(tmp_path / "ref", cfg, cache_dir).path)  # one node, no Ray
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(cfg.to_dict()))

    temp = Path(tempfile.mkdtemp(prefix="dgc", dir="/tmp"))  # short: Ray's socket paths
    env = {**os.environ, "RAY_AUTH_MODE": "disabled", "RAY_USAGE_STATS_ENABLED": "0"}
    port, node2_port = _free_port(), _free_port()
    out = tmp_path / "job"
    driver = None
    try:
        _ray("start", "--head", "--port", str(port), "--node-ip-address", HOST, "--num-cpus", "1",
             "--include-dashboard", "false", "--disable-usage-stats", "--temp-dir", str(temp), env=env)
        _ray("start", "--address", f"{HOST}:{port}", "--node-ip-address", HOST, "--num-cpus", "1",
             "--node-manager-port", str(node2_port), "--disable-usage-stats", env=env)
        raylet2, node2 = _raylet_node_id(node2_port)
        driver = subprocess.Popen([sys.executable, "-m", "datagen.cli", "run", "--address", f"{HOST}:{port}",
                                   "--out", str(out), "--config", str(tmp_path / "job.yaml"), "--cache", cache_dir,
                                   "--no-progress"], cwd=REPO, env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True)
        # kill the second node while it runs a shard, once a shard has finished (mid-job); where
        # each shard started is noted from its progress file
        deadline, killed, started = time.monotonic() + 400, None, {}
        while killed is None and driver.poll() is None and time.monotonic() < deadline:
            ledger = {i: _json(JobDir(out).ledger_path(i)) for i in range(4)}
            for i in range(4):
                node = _json(JobDir(out).progress_path(i)).get("node")
                if node and i not in started:
                    started[i] = node
            running_on_2 = [i for i in range(4) if not ledger[i] and started.get(i) == node2]
            if running_on_2 and any(ledger.values()):  # the node dies: its raylet and the workers it started
                for pid in _descendants(raylet2):
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
                killed = running_on_2[0]
            time.sleep(0.1)
        log, _ = driver.communicate(timeout=600)
        assert killed is not None, f"the second node ran no shard after the first one finished:\n{log}"
        assert driver.returncode == 0, log
    finally:
        if driver is not None and driver.poll() is None:
            driver.kill()
        for session in temp.glob("session_2*"):  # this cluster's processes only (never `ray stop`)
            for pid in cluster_processes(str(session)):
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        subprocess.run(["rm", "-rf", str(temp)], check=False)
    entries = JobDir(out).finished()
    nodes = {i: e["node"] for i, e in entries.items()}
    assert sorted(nodes) == [0, 1, 2, 3]
    head = next(n for n in nodes.values() if n != node2)
    assert set(started.values()) == {head, node2}, started  # shards ran on both nodes
    assert nodes[killed] == head  # the shard the dead node was running was retried on the head
    rows = comparable_rows(out)
    assert len({r["grasp_id"] for r in rows}) == len(rows) == len(reference)  # none lost, none twice
    assert rows == reference
