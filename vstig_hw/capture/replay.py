"""Faithful-timing replay: every record leaves at its own absolute deadline.

Each deadline is `start + (t - t0) / speed`, computed from the first record,
never from the previous send, so per-frame sleep error does not accumulate
(python-can's issue #1372).

Waiting: a sleep wakes late by the kernel's timer slack (50 us) plus the
wake-up, 60-80 us at the median on our 2-core machines, idle or loaded, with a
tail of milliseconds when the machine is busy. We sleep short of each deadline
by the median overshoot our own sleeps have shown (tracked as a running median,
so one preempted sleep moves it by a step, not by the spike), then spin the few
microseconds left. Spinning longer (we spun the last 0.2 ms) costs the tail: a
thread that burns its time slice is the one the scheduler preempts, for
milliseconds, on a loaded machine. On Linux the replaying thread also asks for
a 1 us timer slack while it replays (prctl PR_SET_TIMERSLACK; restored after),
which brings the median overshoot from ~65 us to ~15 us.

Where permitted (root, or CAP_SYS_NICE, or an RLIMIT_RTPRIO above 0) the
replaying thread also runs under SCHED_FIFO at a modest real-time priority
(`REALTIME_PRIORITY`) while it replays, so another process's time slice cannot
push a deadline back by milliseconds; otherwise it keeps normal scheduling,
silently (`ReplayResult.scheduling` says which, for --verbose). Deadlines stay
absolute either way.

A stop (Ctrl-C, SIGTERM) wakes the sleep at once and nothing is sent after it,
however long the gap: no spinning to the deadline. `skip_gaps` shortens any
wait longer than that many seconds to it (python-can's player `--skip`);
`ignore_timestamps` sends back to back (canplayer -t).
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

from .records import Record

__all__ = ["ReplayResult", "replay"]

SLEEP_OVERSHOOT = 60e-6  # the first guess of how late a sleep wakes (50 us timer slack plus the wake-up)
_MEDIAN_STEP = 2e-6  # how far one sleep moves the running median of the overshoot
_PR_SET_TIMERSLACK, _PR_GET_TIMERSLACK = 29, 30  # linux/prctl.h
FINE_TIMER_SLACK_NS = 1000
REALTIME_PRIORITY = 10  # SCHED_FIFO 1..99: above every normal process, below the kernel's IRQ threads (50)


@contextlib.contextmanager
def realtime_scheduling(priority: int = REALTIME_PRIORITY) -> Iterator[str]:
    """This thread under SCHED_FIFO for the duration, where permitted; yields what it runs under, in words."""
    setter = getattr(os, "sched_setscheduler", None)
    if setter is None:
        yield "normal scheduling (this system has no SCHED_FIFO)"
        return
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)  # pid 0: this thread (Linux tasks)
    try:
        setter(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        why = "needs root or CAP_SYS_NICE" if exc.errno == errno.EPERM else os.strerror(exc.errno or 0)
        yield f"normal scheduling (SCHED_FIFO {why})"
        return
    try:
        yield f"SCHED_FIFO priority {priority}"
    finally:
        with contextlib.suppress(OSError):
            setter(0, policy, param)


@contextlib.contextmanager
def fine_timer_slack() -> Iterator[None]:
    """This thread's timer slack at 1 us for the duration (Linux; elsewhere nothing changes)."""
    if not sys.platform.startswith("linux"):
        yield
        return
    import ctypes

    prctl = ctypes.CDLL(None, use_errno=True).prctl
    previous = prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0)
    changed = previous > 0 and prctl(_PR_SET_TIMERSLACK, FINE_TIMER_SLACK_NS, 0, 0, 0) == 0
    try:
        yield
    finally:
        if changed:
            prctl(_PR_SET_TIMERSLACK, previous, 0, 0, 0)


@dataclass
class ReplayResult:
    frames: int = 0
    logged: float = 0.0  # logged duration, first to last record, divided by speed
    took: float = 0.0  # first send to last send
    skipped: float = 0.0  # waiting left out by skip_gaps / ignore_timestamps, in replay seconds
    stopped: bool = False  # a stop ended the replay before the last record
    lateness: list[float] = field(default_factory=list)  # per frame, send time minus deadline (if asked)
    sleep_overshoot: float = SLEEP_OVERSHOOT  # the running median of how late our sleeps woke
    scheduling: str = ""  # what the replaying thread ran under (SCHED_FIFO, or normal and why)


class _Waiter:
    """Waits for a deadline: sleeps short of it by the median overshoot seen so far, spins the rest."""

    def __init__(self, clock: Callable[[], float], sleep: Callable[[float], object], stop: threading.Event) -> None:
        self.clock, self.sleep, self.stop = clock, sleep, stop
        self.overshoot = SLEEP_OVERSHOOT

    def until(self, deadline: float) -> bool:
        """Wait for `deadline`; False at once if a stop came first (then nothing should be sent)."""
        clock = self.clock
        asked = deadline - clock() - self.overshoot
        if asked > 0:
            slept_from = clock()
            self.sleep(asked)
            if self.stop.is_set():
                return False
            late = clock() - slept_from - asked
            self.overshoot = max(0.0, self.overshoot + (_MEDIAN_STEP if late > self.overshoot else -_MEDIAN_STEP))
        while clock() < deadline:
            pass
        return not self.stop.is_set()


def replay(records: Iterable[Record], send: Callable[[Record], None], *, speed: float = 1.0,
           stop: threading.Event | None = None, skip_gaps: float | None = None, ignore_timestamps: bool = False,
           keep_lateness: bool = False, clock: Callable[[], float] = time.perf_counter,
           sleep: Callable[[float], object] | None = None, realtime: bool = True) -> ReplayResult:
    """Call `send` for each record at its deadline; `clock` and `sleep` are for tests (default: the real ones).

    `realtime`: run under SCHED_FIFO where permitted (see the module's notes).
    """
    if speed <= 0:
        raise ValueError(f"speed must be positive, got {speed}")
    if skip_gaps is not None and skip_gaps < 0:
        raise ValueError(f"skip_gaps must not be negative, got {skip_gaps}")
    scheduling = realtime_scheduling() if realtime else contextlib.nullcontext("normal scheduling (not asked)")
    with fine_timer_slack(), scheduling as scheduled:
        result = _replay(records, send, speed, stop or threading.Event(), 0.0 if ignore_timestamps else skip_gaps,
                         keep_lateness, clock, sleep)
    result.scheduling = scheduled
    return result


def _replay(records: Iterable[Record], send: Callable[[Record], None], speed: float, stop: threading.Event,
            skip_gaps: float | None, keep_lateness: bool, clock: Callable[[], float],
            sleep: Callable[[float], object] | None) -> ReplayResult:
    result = ReplayResult()
    waiter = _Waiter(clock, sleep or stop.wait, stop)  # stop.wait: a stop wakes the sleep at once
    start = t0 = previous = None
    first_sent = last_sent = 0.0
    for record in records:
        if stop.is_set():
            result.stopped = True
            break
        if t0 is None or start is None or previous is None:
            t0, start, previous = record.t, clock(), record.t
        gap = (record.t - previous) / speed
        if skip_gaps is not None and gap > skip_gaps:
            result.skipped += gap - skip_gaps
        previous = record.t
        deadline = start + (record.t - t0) / speed - result.skipped
        if not waiter.until(deadline):
            result.stopped = True
            break
        send(record)
        last_sent = clock()
        if result.frames == 0:
            first_sent = last_sent
        if keep_lateness:
            result.lateness.append(last_sent - deadline)
        result.frames += 1
        result.logged = (record.t - t0) / speed
    result.took = last_sent - first_sent
    result.sleep_overshoot = waiter.overshoot
    return result
