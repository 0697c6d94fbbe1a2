"""The local Ray cluster of a job dies with its driver, even a SIGKILLed one.

``ray.shutdown()`` (the driver's normal end, Ctrl-C, SIGTERM) stops the cluster's processes. A
driver killed with SIGKILL (the OOM killer, ``kill -9``) runs no code: Ray's own processes then
notice it only after ~90 s, and its workers (with their CoACD and MuJoCo children) go on using
the cores. The reaper is a small process the driver starts once its cluster is up, in its own
session, reading a pipe the driver holds open: when the pipe closes (the driver ended, however),
it kills, with SIGKILL, every process of this user whose command line names the cluster's session
directory (GCS server, raylet, monitors) and all their descendants (agents, workers and what
they started), as it last noted them (once a second) and as they are then. After a normal
shutdown there is nothing left to kill.

    reaper = start_reaper(session_dir)   # after ray.init
    ...
    reaper.close()                       # after ray.shutdown (or never: the driver's death closes it)

The session directory (``<temp dir>/session_<time>_<pid>``) is unique to one cluster, so a rerun
of the job, whose cluster has another one, is never touched.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

__all__ = ["Reaper", "cluster_processes", "start_reaper"]


def _procs() -> dict[int, tuple[int, int, bytes]]:
    """pid -> (parent pid, start time in clock ticks, command line) of this user's processes."""
    out, uid = {}, os.getuid()
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if d.stat().st_uid != uid:
                continue
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            out[int(d.name)] = (int(fields[1]), int(fields[19]), (d / "cmdline").read_bytes())
        except (OSError, ValueError, IndexError):
            continue
    return out


def cluster_processes(session_dir: str) -> dict[int, int]:
    """pid -> start time of this user's processes naming ``session_dir`` on their command line
    and of all their descendants (not this process)."""
    procs, me = _procs(), os.getpid()
    key = os.fsencode(session_dir)
    found = {p for p, (_, _, cmd) in procs.items() if key in cmd and p != me}
    children: dict[int, list[int]] = {}
    for p, (pp, _, _) in procs.items():
        children.setdefault(pp, []).append(p)
    todo = list(found)
    while todo:
        for c in children.get(todo.pop(), []):
            if c not in found and c != me:
                found.add(c)
                todo.append(c)
    return {p: procs[p][1] for p in sorted(found)}


class Reaper:
    """The driver's end of the reaper (`start_reaper`)."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc = proc

    def close(self) -> None:
        """Let the reaper sweep (nothing is left after ``ray.shutdown``) and wait for it."""
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def start_reaper(session_dir: str) -> Reaper:
    """Start the reaper of the cluster whose session directory is ``session_dir``."""
    proc = subprocess.Popen([sys.executable, "-m", "workers.reaper", session_dir], stdin=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            cwd=str(Path(__file__).resolve().parents[1]))
    return Reaper(proc)


def main(session_dir: str, every_s: float = 1.0) -> None:
    """Until the driver's end of stdin closes, note the cluster's processes every ``every_s``
    (when the driver dies, some of Ray's processes die with it at once and leave their children,
    the agents and workers, to init: the last note still has them); then kill the noted and the
    current ones, each only if it is still the process that was noted (same start time)."""
    import select

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C is the driver's to handle
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    noted: dict[int, int] = {}
    fd = sys.stdin.fileno()
    while True:
        if select.select([fd], [], [], every_s)[0]:
            if not os.read(fd, 1 << 16):
                break
        else:
            noted = cluster_processes(session_dir)
    now = _procs()
    for pid, started in {**noted, **cluster_processes(session_dir)}.items():
        if pid in now and now[pid][1] == started:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass


if __name__ == "__main__":
    main(sys.argv[1])
