"""Faithful-timing replay: every record leaves at its own absolute deadline.

Each deadline is `start + (t - t0) / speed`, computed from the first record,
never from the previous send, so per-frame sleep error does not accumulate
(python-can's MessageSync sleeps per gap and drifts: its issue #1372). Waiting
is hybrid: sleep until `spin` seconds before the deadline (OS sleeps overshoot
by ~0.1 ms), then spin on the clock for the rest; a short spin also
leaves the CPU to others, so a loaded machine preempts us less.

A stop (Ctrl-C, SIGTERM) wakes the sleep at once and nothing is sent after it,
however long the gap. `skip_gaps` shortens any wait longer than that many
seconds to it (python-can's player `--skip`); `ignore_timestamps` sends
back to back (canplayer -t).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from .records import Record

__all__ = ["ReplayResult", "replay"]

SPIN = 0.0002  # seconds before a deadline at which sleeping stops and spinning starts (sleep overshoots ~0.1 ms)


@dataclass
class ReplayResult:
    frames: int = 0
    logged: float = 0.0  # logged duration, first to last record, divided by speed
    took: float = 0.0  # first send to last send
    skipped: float = 0.0  # waiting left out by skip_gaps / ignore_timestamps, in replay seconds
    stopped: bool = False  # a stop ended the replay before the last record
    lateness: list[float] = field(default_factory=list)  # per frame, send time minus deadline (if asked)


def replay(records: Iterable[Record], send: Callable[[Record], None], *, speed: float = 1.0,
           stop: threading.Event | None = None, skip_gaps: float | None = None, ignore_timestamps: bool = False,
           keep_lateness: bool = False, clock: Callable[[], float] = time.perf_counter) -> ReplayResult:
    if speed <= 0:
        raise ValueError(f"speed must be positive, got {speed}")
    if skip_gaps is not None and skip_gaps < 0:
        raise ValueError(f"skip_gaps must not be negative, got {skip_gaps}")
    if ignore_timestamps:
        skip_gaps = 0.0
    stop = stop or threading.Event()  # never set when none is given: its wait() is a plain sleep
    result = ReplayResult()
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
        remaining = deadline - clock()
        if remaining > SPIN and stop.wait(remaining - SPIN):
            result.stopped = True
            break
        while clock() < deadline:
            pass
        if stop.is_set():
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
    return result
