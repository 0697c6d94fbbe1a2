"""Long-lived interpreters that process objects for `isolate.process_isolated`, one at a time.

A fresh interpreter per object costs ~2.5 s before any work (importing torch, trimesh, CoACD,
MuJoCo and, under ``multiprocessing``'s spawn, the caller's main module): more than processing a
typical object takes (median ~0.4 s). An `IsolatedWorker` is started once and serves object
after object over two pipes; the isolation stays: a worker that overruns its time limit is
killed and one that dies (native crash) is replaced, so either still costs only its object.

The worker is ``python -m datagen.objects.worker_main``, never a copy of the caller: unlike
``multiprocessing``'s spawn it does not re-import the caller's main module, so a script without
an ``if __name__ == "__main__":`` guard is not run again inside it. It gets the caller's
``sys.path`` first, then per request the step, its arguments and the caller's environment.

Idle workers wait in a pool (`take` / `give`); each serves at most `MAX_TASKS` objects, then a
fresh one takes over (memory that native code never returns stays bounded). The pool's workers
are killed when the caller exits.
"""

from __future__ import annotations

import atexit
import os
import pickle
import subprocess
import sys
import threading
from multiprocessing.connection import Connection

from datagen._interrupt import sigint_blocked

__all__ = ["IsolatedWorker", "MAX_TASKS", "give", "serve", "take"]

MAX_TASKS = 100  #: objects one worker serves before it is replaced
START_TIMEOUT_S = 300.0  #: how long a new worker may take to import the processing code (a loaded machine)


class IsolatedWorker:
    """One worker interpreter (see the module docstring)."""

    def __init__(self) -> None:
        r_req, w_req = os.pipe()
        r_res, w_res = os.pipe()
        try:
            with sigint_blocked():  # until the worker has set its Ctrl-C policy ("die")
                self.proc = subprocess.Popen([sys.executable, "-m", "datagen.objects.worker_main", str(r_req),
                                              str(w_res)],
                                             pass_fds=(r_req, w_res))
        finally:
            os.close(r_req)
            os.close(w_res)
        self._requests = Connection(w_req, readable=False)
        self._results = Connection(r_res, writable=False)
        self.tasks = 0
        self._ready = False
        self._requests.send(list(sys.path))

    def wait_ready(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Wait until the worker has imported the processing code (once): an object's time limit
        then counts its processing, not the interpreter's start. `TimeoutError` after
        ``timeout_s``, `EOFError` if the worker died starting."""
        if self._ready:
            return
        if not self._results.poll(timeout_s):
            raise TimeoutError
        self._results.recv()  # ("ready", None)
        self._ready = True

    def alive(self) -> bool:
        return self.proc.poll() is None

    def submit(self, payload: tuple) -> None:
        """Send one request, ``(step, args)``; raises `BrokenPipeError` if the worker is gone."""
        self._requests.send((payload, dict(os.environ)))
        self.tasks += 1

    def result(self, timeout_s: float):
        """The request's reply, `TimeoutError` after ``timeout_s``, `EOFError` if the worker died."""
        if not self._results.poll(timeout_s):
            raise TimeoutError
        return self._results.recv()

    def exitcode(self, wait_s: float = 5.0) -> int | None:
        try:
            return self.proc.wait(wait_s)
        except subprocess.TimeoutExpired:
            return None

    def kill(self) -> None:
        """End the process at once (from any thread: a caller waiting for its reply gets `EOFError`)."""
        if self.proc.poll() is None:
            try:
                self.proc.kill()
            except ProcessLookupError:
                pass

    def close(self) -> None:
        """Kill the process and release its pipes (by the thread that owns the worker)."""
        self.kill()
        self.exitcode()
        for conn in (self._requests, self._results):
            if not conn.closed:
                conn.close()


_idle: list[IsolatedWorker] = []
_lock = threading.Lock()
_registered = False


def take() -> IsolatedWorker:
    """An idle live worker of this process, else a new one."""
    global _registered
    with _lock:
        while _idle:
            w = _idle.pop()
            if w.alive():
                return w
            w.close()
        if not _registered:
            atexit.register(_shutdown)
            _registered = True
    return IsolatedWorker()


def give(w: IsolatedWorker) -> None:
    """Return a worker whose last request was answered: kept idle, or ended after `MAX_TASKS`."""
    if w.tasks >= MAX_TASKS or not w.alive():
        w.close()
        return
    with _lock:
        _idle.append(w)


def _shutdown() -> None:
    with _lock:
        workers, _idle[:] = list(_idle), []
    for w in workers:
        w.close()


def serve(requests: Connection, results: Connection) -> None:
    """The worker's loop: one reply per request until the caller closes the pipe."""
    sys.path[:] = requests.recv()
    import datagen.objects.process  # noqa: F401 - the default step's imports (trimesh, CoACD, MuJoCo), once

    results.send(("ready", None))
    while True:
        try:
            data = requests.recv_bytes()
        except EOFError:
            return
        try:
            (step, args), env = pickle.loads(data)
        except Exception as exc:  # noqa: BLE001 - e.g. a step defined in the caller's __main__
            results.send(("load_error", f"{type(exc).__name__}: {' '.join(str(exc).split())}"))
            continue
        os.environ.clear()
        os.environ.update(env)
        results.send(("ok", step(*args)))

