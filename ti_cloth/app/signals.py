"""Stopping a run cleanly: SIGTERM (what `timeout`, job schedulers and `kill` send) is handled
like Ctrl-C, so an interrupted run finishes its frame, keeps every frame written and still
assembles its GIF/MP4; signals that arrive while those are assembled are held until they are
done. Exit codes follow the shell's convention, 128 + the signal number (130, 143)."""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


class Stopped(KeyboardInterrupt):
    """A stop signal received while a run was in progress (a KeyboardInterrupt, so code that
    already ends cleanly on Ctrl-C ends cleanly on it too)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def signal_number(stop: KeyboardInterrupt) -> int:
    """The signal that stopped a run: Stopped's, or SIGINT for a plain KeyboardInterrupt."""
    return int(getattr(stop, "signum", signal.SIGINT))


def exit_code(stop: KeyboardInterrupt) -> int:
    """128 + the signal's number: 130 for Ctrl-C, 143 for SIGTERM."""
    return 128 + signal_number(stop)


def _raise_stopped(signum, frame):
    raise Stopped(signum)


@contextmanager
def stop_signals_raise():
    """Within the block SIGINT and SIGTERM raise Stopped (outside the main thread: no change).
    A signal the process was started ignoring stays ignored: a shell script's `ti-cloth run &`
    ignores Ctrl-C, which is meant for the script's foreground job."""
    with _handlers(_raise_stopped):
        yield


@contextmanager
def stop_signals_held():
    """Within the block SIGINT and SIGTERM are noted in the yielded list, not acted on."""
    held: list[int] = []
    with _handlers(lambda signum, frame: held.append(signum)):
        yield held


@contextmanager
def _handlers(handler):
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS
                if signal.getsignal(s) is not signal.SIG_IGN}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
