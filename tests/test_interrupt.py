"""Ctrl-C policies (`datagen._interrupt`): a child that dies of SIGINT does so at once and
silently, one that ignores it lives on; a deferred SIGINT becomes a KeyboardInterrupt only after
the block."""

import multiprocessing as mp
import os
import signal
import time

import pytest

from datagen._interrupt import on_sigint, sigint_blocked, sigint_deferred


def _sleeper(policy: str, ready) -> None:
    on_sigint(policy)
    ready.set()
    time.sleep(30)


@pytest.mark.parametrize("policy, ends", [("die", True), ("ignore", False)])
def test_a_child_dies_of_sigint_or_ignores_it(policy, ends):
    ctx = mp.get_context("spawn")
    ready = ctx.Event()
    proc = ctx.Process(target=_sleeper, args=(policy, ready), daemon=True)
    with sigint_blocked():
        proc.start()
    try:
        os.kill(proc.pid, signal.SIGINT)  # while it starts: held until it has set its policy
        if ends:  # at once, by the signal (no KeyboardInterrupt, so no traceback)
            proc.join(60)
            assert proc.exitcode == -signal.SIGINT and not ready.is_set()
        else:
            assert ready.wait(60)
            os.kill(proc.pid, signal.SIGINT)
            proc.join(1)
            assert proc.is_alive()
    finally:
        proc.kill()
        proc.join()


def test_the_block_restores_the_callers_mask():
    before = signal.pthread_sigmask(signal.SIG_BLOCK, set())
    with sigint_blocked():
        assert signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, set())
    assert signal.pthread_sigmask(signal.SIG_BLOCK, set()) == before


def test_a_deferred_sigint_is_raised_after_the_block():
    done = []
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with sigint_deferred():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.1)  # the handler runs here: held, not raised
                done.append("after the signal")
        assert done == ["after the signal"]
        with sigint_deferred():  # no signal: nothing raised
            pass
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, old)
