"""Ctrl-C, SIGTERM and SIGHUP become one Event the loop checks, so shutdown is never mid-frame.

SIGHUP is what a closed terminal (or a dropped ssh session) sends: it ends a command the way
Ctrl-C does, files closed and counters printed, instead of killing it with its capture unfinished.

A second signal while the first is still being acted on ends the process at once (the
signal's default action), so a stop that cannot finish (a device that does not let go)
never leaves the user with a command that ignores Ctrl-C. Captures survive that: they are
flushed every tick and readable after a kill. A signal within `SAME_STOP_S` of the first is
the same stop, not a second one: `timeout -s INT` signals its command and then the command's
process group, so one timeout can deliver two signals a few microseconds apart.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["SAME_STOP_S", "stop_on_signals"]

SAME_STOP_S = 1.0  # a repeat this soon is one sender's echo (timeout(1)); a person's second Ctrl-C comes later


@contextmanager
def stop_on_signals() -> Iterator[threading.Event]:
    """An Event set by SIGINT, SIGTERM or SIGHUP while the block runs (handlers restored after)."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop  # signals only reach the main thread; the caller stops us some other way
        return
    first_at: list[float] = []

    def handler(signum: int, frame: FrameType | None) -> None:
        if not first_at:
            first_at.append(time.monotonic())
            stop.set()
            return
        if time.monotonic() - first_at[0] < SAME_STOP_S:
            return  # the same stop, delivered twice
        sys.stderr.write("stopping now\n")  # the second signal: no more waiting for a clean stop
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)

    stopping = [signal.SIGINT, signal.SIGTERM]
    hangup = getattr(signal, "SIGHUP", None)  # not on Windows
    if hangup is not None and signal.getsignal(hangup) is not signal.SIG_IGN:  # nohup ignores it: keep running
        stopping.append(hangup)
    previous = {sig: signal.signal(sig, handler) for sig in stopping}
    try:
        yield stop
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
