"""The Ray cluster of a job: a local one on loopback (its temp dir, its reaper) or a given address.

Without an address (argument or ``RAY_ADDRESS``) the driver starts a local Ray with every core, no
dashboard, every port on the loopback interface and its temp dir inside the job directory
(`start_local_ray`). Ray puts Unix sockets under ``<temp>/session_<date>_<pid>/sockets/``, and a
socket path may not exceed 107 bytes, so when ``<job>/ray`` is longer than `MAX_RAY_TEMP_LEN`
characters a short ``/tmp/dg-ray-XXXX`` is used instead (named by a hash of the job path; printed,
and removed at the end). With an address it joins that cluster (`connect`); the job directory and
the objects cache must then be on a file system every node sees, and every node needs this
package installed.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
from pathlib import Path

from datagen._interrupt import raise_on_sigterm

from .job import JobConfig, JobDir, JobError

__all__ = ["LOOPBACK", "MAX_RAY_TEMP_LEN", "connect", "error_line", "start_local_ray", "start_reaper_for", "stop_local_ray",
           "worker_slots"]

MAX_RAY_TEMP_LEN = 40
LOOPBACK = "127.0.0.1"  # the local cluster's node address: Ray then listens on loopback only


def error_line(exc: BaseException) -> str:
    """One line naming an exception from a Ray task: its cause, without traceback or colours."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        exc = cause
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return f"{type(exc).__name__}: {lines[-1] if lines else ''}"


def _ray_temp_dir(job: JobDir) -> tuple[str, bool]:
    """(temp dir, is_private_tmp)."""
    inside = job.path / "ray"
    if len(str(inside)) <= MAX_RAY_TEMP_LEN:
        inside.mkdir(mode=0o700, parents=True, exist_ok=True)
        os.chmod(inside, 0o700)
        return str(inside), False
    # a name fixed by the job path: a resumed run reuses (and finally removes) a killed run's dir
    short = Path("/tmp") / f"dg-ray-{hashlib.sha256(str(job.path).encode()).hexdigest()[:10]}"
    short.mkdir(mode=0o700, exist_ok=True)
    if short.owner() != __import__("getpass").getuser():
        raise JobError(f"{short} (Ray's temp dir for this job) belongs to another user; remove it")
    os.chmod(short, 0o700)
    return str(short), True


class _DropNotice(logging.Filter):
    def __init__(self, prefix: str) -> None:
        super().__init__()
        self.prefix = prefix

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(self.prefix)


def start_local_ray(ray, job: JobDir, num_cpus: int | None, log=print) -> str | None:
    """Start the job's local Ray: every core (or ``num_cpus``), no dashboard, its temp dir private
    (`_ray_temp_dir`), every port on the loopback interface. Returns the temp dir to remove at the
    end (a ``/tmp/dg-ray-*`` one), else None.

    Ray binds its gRPC servers (GCS, raylet, object manager, each worker's), its agents and the
    metrics exporter to the loopback interface when the node's address is loopback, but on Linux
    it replaces a loopback ``_node_ip_address`` by the machine's address unless its single-machine
    mode is on (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, the default on macOS and Windows; read
    when ``ray`` is imported, so it is set here on Ray's constant for the duration of ``init``).
    """
    tmp, private = _ray_temp_dir(job)
    if private:
        log(f"ray temp dir {tmp} (the job path is too long for Ray's Unix sockets)")
    constants = getattr(getattr(ray, "_private", None), "ray_constants", None)
    single = getattr(constants, "ENABLE_RAY_CLUSTER", None)
    if single is not None:
        constants.ENABLE_RAY_CLUSTER = False
    notice = logging.getLogger("ray._private.authentication.authentication_token_setup")
    quiet = _DropNotice("Token authentication is enabled")  # the default, said at every start; a warning
    notice.addFilter(quiet)                                   # that it is disabled still shows
    try:
        ray.init(num_cpus=num_cpus or os.cpu_count(), include_dashboard=False, _temp_dir=tmp,
                 _node_ip_address=LOOPBACK, log_to_driver=False, configure_logging=False)
    finally:
        notice.removeFilter(quiet)
        if single is not None:
            constants.ENABLE_RAY_CLUSTER = single
    os.chmod(tmp, 0o700)  # Ray makes it world-writable; its sockets and logs are ours only
    node_ip = ray.util.get_node_ip_address()
    if node_ip not in (LOOPBACK, "::1"):
        log(f"warning: Ray {ray.__version__} put the local cluster on {node_ip}, not on the loopback interface: "
            "its ports listen on every interface; on a shared network, firewall them")
    return tmp if private else None


def stop_local_ray(ray) -> None:
    """``ray.shutdown()`` of a local cluster this process started, 1 s sooner.

    Ray's shutdown stops its processes one after another, each with SIGTERM and up to 1 s to
    exit. The autoscaler monitor ignores SIGTERM, so every job waited the full second for it (Ray
    2.60: 1.37 -> 0.33 s per shutdown on the project's machine). A local cluster has one node and
    never scales: the monitor is killed first, then Ray stops the rest as usual. The monitor is
    looked up through Ray's private node object; where there is none (a driver connected to a
    cluster owns no Ray process, or another Ray version), this is plain ``ray.shutdown()``."""
    node = getattr(getattr(getattr(ray, "_private", None), "worker", None), "_global_node", None)
    for info in (getattr(node, "all_processes", None) or {}).get("monitor", []):
        proc = getattr(info, "process", None)
        try:
            if proc is not None and proc.poll() is None:
                proc.kill()
                proc.wait(timeout=5)
        except Exception:  # noqa: BLE001 - ray.shutdown below stops it the slow way
            pass
    ray.shutdown()


def worker_slots(cfg: JobConfig, address: str | None, num_cpus: int | None) -> tuple[int, bool, bool]:
    """(shard tasks that can run at once, whether this connected to a Ray cluster to count them,
    whether the shards get GPUs).

    Local: ``num_cpus`` (or every core) over ``cpus_per_shard``, and this machine's CUDA devices
    over ``gpus_per_shard`` when it has any. A cluster (``address`` or $RAY_ADDRESS, not "local"):
    its CPUs over ``cpus_per_shard``, and its GPUs over ``gpus_per_shard`` when it has GPUs, as Ray
    reports them now. The scarcer resource sets the count: a shard task asks for both."""
    import ray

    address = address or os.environ.get("RAY_ADDRESS") or None
    connected = False
    if address and address != "local":
        if not ray.is_initialized():
            connect(ray, address)
            connected = True
            raise_on_sigterm()
        res = ray.cluster_resources()
        cpus, gpus = res.get("CPU", 1.0), res.get("GPU", 0)
    else:
        import torch

        cpus, gpus = num_cpus or os.cpu_count() or 1, torch.cuda.device_count() if torch.cuda.is_available() else 0
    slots = cpus / cfg.cpus_per_shard
    on_gpus = gpus > 0 and cfg.gpus_per_shard > 0
    if on_gpus:
        slots = min(slots, gpus / cfg.gpus_per_shard)
    return max(1, int(slots + 1e-9)), connected, on_gpus


def start_reaper_for(ray):
    """The reaper of the local cluster just started (`workers.reaper`: it dies with this driver,
    even a SIGKILLed one), or None where Ray does not say its session directory."""
    from .reaper import start_reaper

    node = getattr(getattr(getattr(ray, "_private", None), "worker", None), "_global_node", None)
    try:
        return start_reaper(node.get_session_dir_path())
    except Exception:  # noqa: BLE001 - another Ray version: only ray.shutdown stops the cluster
        return None


def connect(ray, address: str) -> None:
    """Join the Ray cluster at ``address`` (`JobError` naming it when none answers)."""
    try:
        ray.init(address=address, log_to_driver=False)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise JobError(f"--address {address}: cannot connect to a Ray cluster there ({error_line(exc)})",
                       "start it with `ray start --head`, or pass the address `ray status` names") from None
