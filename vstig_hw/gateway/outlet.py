"""One link's way out: a send queue drained under a per-tick budget.

The engine has one outbox; links differ in bandwidth (a CAN bus moves thousands
of frames a second, an e-puck radio a few dozen). So every engine message is
copied into each link's own queue, and each queue keeps the engine's rule: one
pending message per key, newest wins, PUTs first (`OutQueue`). A slow link
therefore never builds a backlog of outdated values, and a fast one never waits
for a slow one.

The budget is a sliding window, not a tick-aligned burst: at most `budget`
messages leave in any `period`-long window. A message goes out the moment the
window allows, so a quiet gateway relays across media within the time it takes
to wake a thread, instead of waiting up to a whole tick; a busy one is held to
the same bandwidth the tick-aligned drain would allow.

What leaves the window goes to the link's `LinkWriter`: written at once while the
device takes it, else queued (bounded) for that link's own thread, so a device that
stops taking data never holds up the loop or another link.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from ..counters import Counters
from ..links.link import Link
from ..outqueue import OutQueue
from ..wire import Message
from .writer import CLOSE_WAIT, TX_QUEUE_LIMIT, LinkWriter

__all__ = ["Outlet", "SendWindow"]

RAW_QUEUE_LIMIT = 10_000  # raw mode keeps every frame; beyond this the oldest are dropped and counted


class SendWindow:
    """At most `budget` sends in any `period` seconds (None: unlimited)."""

    def __init__(self, budget: int | None, period: float) -> None:
        if budget is not None and budget < 1:
            raise ValueError(f"budget must be at least 1 message per tick, got {budget}")
        if period <= 0:
            raise ValueError(f"the tick period must be positive, got {period}")
        self.budget = budget
        self.period = period
        self._sent: deque[float] = deque(maxlen=budget or 1)

    def allowance(self, now: float) -> int:
        if self.budget is None:
            return 1 << 30
        sent = self._sent
        while sent and sent[0] <= now - self.period:
            sent.popleft()
        return self.budget - len(sent)

    def record(self, now: float, count: int) -> None:
        if self.budget is not None:
            if count == 1:
                self._sent.append(now)
            else:
                self._sent.extend([now] * min(count, self.budget))

    def next_free(self) -> float | None:
        """When the window next opens, if it is full now."""
        if self.budget is None or len(self._sent) < self.budget:
            return None
        return self._sent[0] + self.period


class Outlet:
    """A link, its send queue and its budget window."""

    def __init__(self, link: Link[Any], budget: int | None, period: float, *, keep_all: bool = False,
                 tx_queue: int = TX_QUEUE_LIMIT) -> None:
        self.link = link
        self.writer = LinkWriter(link, tx_queue)
        self.window = SendWindow(budget, period)
        self.keep_all = keep_all  # raw mode: a FIFO of every frame, not newest-per-key
        self._newest = OutQueue()
        self._fifo: deque[Message] = deque()
        self.handed = 0  # messages handed to the writer so far (what `Node.drain` waits for)

    @property
    def counters(self) -> Counters:
        return self.link.counters

    def __len__(self) -> int:
        return len(self._fifo) if self.keep_all else len(self._newest)

    def push(self, msg: Message) -> None:
        if not self.keep_all:
            if not self._newest.push(msg):
                self.counters["superseded"] += 1
            return
        if len(self._fifo) >= RAW_QUEUE_LIMIT:
            self._fifo.popleft()
            self.counters["drop_overflow"] += 1
        self._fifo.append(msg)

    def flush(self, now: float) -> float | None:
        """Send what the window allows; returns when to try again if messages wait."""
        waiting = self._fifo if self.keep_all else self._newest
        if not waiting:
            return None
        window = self.window
        if window.budget is None:  # no budget: everything, at once (a raw bridge's hot path)
            if self.keep_all:
                batch = list(self._fifo)
                self._fifo.clear()
            else:
                batch = self._newest.drain()
        else:
            allowed = window.allowance(now)
            if allowed <= 0:
                return window.next_free()
            if self.keep_all:
                fifo = self._fifo
                batch = [fifo.popleft() for _ in range(min(allowed, len(fifo)))]
            else:
                batch = self._newest.drain(allowed)
            window.record(now, len(batch))
        self.handed += len(batch)
        try:
            self.writer.submit(self.link.units_of(batch), len(batch))  # one unit for the batch on a byte stream
        except Exception:  # a transport that broke its promise not to raise: count, keep the loop alive
            self.counters["drop_write_error"] += len(batch)
        return window.next_free() if waiting else None

    def send_now(self, msg: Message, now: float) -> None:
        """Send `msg` ahead of everything queued here, whatever the window (which it still counts against).

        For what must leave before anything queued after it (a confirmed write's probe, see `confirm`):
        queued, a PUT for the same key would replace it.
        """
        self.window.record(now, 1)
        self.handed += 1
        try:
            self.writer.submit(self.link.units_of([msg]), 1)
        except Exception:  # as in `flush`
            self.counters["drop_write_error"] += 1

    def close(self, wait: float = CLOSE_WAIT) -> None:
        """Give the device up to `wait` seconds to take what the writer holds, then stop it. What the window
        still held back, and what the device did not take, is counted as `unsent_at_close`."""
        held = len(self)
        if held:
            self.counters["unsent_at_close"] += held
            self._newest = OutQueue()
            self._fifo.clear()
        self.writer.close(wait)
