"""Ctrl-C and child processes: one clean line from the command, no traceback from its children.

A terminal's Ctrl-C sends SIGINT to the whole foreground process group: the command and every
process it started. Python turns it into a KeyboardInterrupt, so each child would print its own
traceback and a child busy in native code (CoACD, MuJoCo) would notice it only when that code
returns. The command itself prints one line (`datagen.cli.main`); its children follow one of two
policies, set before they run a line of their own code:

- ``"die"``: SIGINT ends the child at once (the kernel's default action), even inside native
  code, without a traceback (object processing: its parent records nothing for an interrupted
  run, and a child orphaned by a killed parent must not go on).
- ``"ignore"``: the child goes on, and its parent, which gets the KeyboardInterrupt, ends it
  (`multiprocessing.Pool.terminate`) (evaluation workers).

A child is started with SIGINT blocked (`sigint_blocked`, around the start), so a Ctrl-C while it
is still importing waits until `on_sigint` sets its policy: pending, it then ends the child
("die") or is dropped ("ignore").

    with sigint_blocked():
        proc.start()            # the child calls on_sigint("die") first

Native code that runs its own threads (SciPy's ``cKDTree.query(workers=-1)``) must not be left by
a KeyboardInterrupt: its threads would go on with freed arrays and crash the interpreter as it
exits. `sigint_deferred` holds a Ctrl-C until such a call has returned.

SIGTERM stops a command as Ctrl-C does (`raise_on_sigterm`: a `Terminated` KeyboardInterrupt),
with its own line and exit code 143.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Iterator

__all__ = ["Terminated", "on_sigint", "raise_on_sigterm", "sigint_blocked", "sigint_deferred", "was_terminated"]


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill PID``, a scheduler stopping the job) in a command's main thread: handled
    like Ctrl-C (the command's cleanup runs, one line, no traceback), exit 143."""


_terminated = threading.Event()


def _terminate(signum, frame):
    _terminated.set()
    raise Terminated


def raise_on_sigterm() -> None:
    """In a command's main thread: SIGTERM raises `Terminated`. Called again after a library that
    installs its own handler (``ray.init`` makes it ``sys.exit(15)``)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _terminate)


def was_terminated() -> bool:
    """Whether SIGTERM arrived: native code that catches the interrupt and raises its own
    KeyboardInterrupt (Ray's ``ray.wait``) loses the `Terminated` type."""
    return _terminated.is_set()


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """Block SIGINT in the calling thread; processes started inside inherit the block. The
    thread's previous mask is restored on exit (a SIGINT that arrived meanwhile is then handled)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def on_sigint(policy: str) -> None:
    """In a child process (its main thread), first thing: ``"die"`` or ``"ignore"`` on SIGINT (see
    the module docstring), then unblock it. SIGTERM gets its default action back (a forked child
    inherits the command's `raise_on_sigterm`, and ``Pool.terminate`` ends its workers with
    SIGTERM: they must die quietly, not raise)."""
    if policy not in ("die", "ignore"):
        raise ValueError(f"on_sigint: policy must be 'die' or 'ignore', got {policy!r}")
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_DFL if policy == "die" else signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
    """In the main thread, hold a SIGINT that arrives inside the block (or arrived just before it
    and is not handled yet) until the block ends, then handle it as before (KeyboardInterrupt).
    Elsewhere a no-op: only the main thread gets KeyboardInterrupt."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if held:
            if callable(old):
                old(signal.SIGINT, None)  # Python's default handler raises KeyboardInterrupt
            elif old == signal.SIG_DFL:
                os.kill(os.getpid(), signal.SIGINT)
