"""One link's writer: the gateway's loop hands units over and never waits on a device.

A radio nobody reads, a CAN adapter whose queue is full, a TCP peer that stopped
reading: each would hold a blocking write, and with it the loop every other link
depends on. So each link gets its own bounded queue and writer thread:

* While the device takes what we send, the loop writes it at once itself
  (`write_nowait`: a serial port's fd, a Zenoh publisher that drops under
  congestion), with no hand-off to another thread. A transport that cannot write
  without waiting takes nothing that way (its default), so all goes to the queue.
* What the device does not take at once waits in this link's queue, and this
  link's thread alone waits for the device (its transport's blocking `write`).
* The outlet hands over no more while `room` is spent: the writer holds at most
  `hold` messages the device has not taken (`WRITER_HOLD`), and what else waits
  stays in the outlet, shared fairly among its sources (`fairshare`). When the
  device takes enough that room opens again, `on_room` is called (from this
  link's thread) so the outlet is flushed again at once. A device that has left
  no room for `STALL_TOLD_AFTER` seconds is logged once, and once when it takes
  everything again.
* The queue holds at most `limit` messages whoever submits. When it is full the
  oldest queued units are dropped and counted as `tx_overflow` (what is newest
  matters most to a stigmergy), logged once when an episode starts and once when
  it ends.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from ..links.link import Link

__all__ = ["TX_QUEUE_LIMIT", "WRITER_HOLD", "LinkWriter"]

log = logging.getLogger(__name__)

TX_QUEUE_LIMIT = 1024  # messages waiting per link: ~1 s of a 115200-baud cobs8 radio
WRITER_HOLD = 64  # messages held for a slow device before the outlet keeps the rest: ~70 ms of that radio
STALL_TOLD_AFTER = 1.0  # seconds a device may leave no room before it is logged (a busy bus's brief spells are not)
CLOSE_WAIT = 1.0  # seconds close() gives the device to take what is queued


class LinkWriter:
    # declared: the compiled outlets (vstig_hw/_cext/outlet.c) read these too
    hold: int  # messages held for a slow device before the outlet keeps the rest
    idle: bool  # nothing queued or being written (see __init__)

    def __init__(self, link: Link[Any], limit: int = TX_QUEUE_LIMIT, *, hold: int = WRITER_HOLD,
                 on_room: Callable[[], None] | None = None) -> None:
        if limit < 1:
            raise ValueError(f"a link's send queue holds at least 1 message, got {limit}")
        if hold < 1:
            raise ValueError(f"a writer holds at least 1 message, got {hold}")
        self.link = link
        self.limit = limit
        self.hold = hold
        self._on_room = on_room
        self._full = False  # `room` was spent: tell `on_room` when it opens again
        self._full_since: float | None = None  # when room was first found spent in this episode
        self._told = False  # the episode was logged (a long stall, or drops): its end is logged too
        self._write = link.write
        self._write_nowait = link.write_nowait
        self._queue: deque[tuple[Any, int]] = deque()  # (unit, messages it carries)
        self._queued = 0  # messages in _queue
        self._rest: tuple[Any, int] | None = None  # the tail of a unit the loop began
        self._busy = False  # the thread is in a device write
        self._writing = 0  # messages the unit in that write carries: they still wait for the device
        # Nothing queued or being written: the loop's write goes straight to the device (the compiled outlets
        # look at this alone). Changed only under the lock, in one step, so it is never True while a unit waits.
        self.idle = True
        self._closing = False
        self._dropped_in_episode = 0
        self._lock = threading.Lock()  # entered directly on the hot path (a Condition's `with` is Python code)
        self._cond = threading.Condition(self._lock)
        self._thread: threading.Thread | None = None

    def __len__(self) -> int:
        return self._queued

    def tap(self, written: Callable[[Any], None]) -> Callable[[], None]:
        """Tell `written(unit)` of every unit (or a byte unit's part) the device took from now on (a recording
        bridge's sends); returns the call that stops it. The device's writes are wrapped while tapped, so a
        writer nobody taps pays nothing."""
        write, write_nowait = self._write, self._write_nowait

        def tapped_write(unit: Any) -> None:
            write(unit)
            written(unit)

        def tapped_write_nowait(unit: Any) -> Any:
            rest = write_nowait(unit)
            if rest is None:
                written(unit)
            elif isinstance(unit, bytes) and len(rest) < len(unit):  # a byte stream took the unit's head
                written(unit[:len(unit) - len(rest)])
            return rest

        self._write, self._write_nowait = tapped_write, tapped_write_nowait

        def untap() -> None:
            self._write, self._write_nowait = write, write_nowait

        return untap

    def room(self) -> int:
        """How many more messages the outlet may hand over now (at most `hold` wait for the device)."""
        if not (self._queued or self._writing) and self._rest is None:  # holds nothing (only this caller adds)
            return self.hold
        with self._lock:  # as the writer's thread looks at `_full` after each write: no wake-up lost between
            held = self._queued + self._writing + (0 if self._rest is None else self._rest[1])
            room = self.hold - held
            if room <= 0:
                self._full = True
                now = time.monotonic()
                if self._full_since is None:
                    self._full_since = now
                elif now - self._full_since >= STALL_TOLD_AFTER:
                    self._tell_stall()
            return room

    def _tell_stall(self) -> None:
        if not self._told:
            self._told = True
            log.warning("%s: the device does not take what we send; its messages wait while the other links "
                        "carry on", self.link.name)

    def submit(self, units: list[Any], messages: int) -> None:
        """Send `units` (carrying `messages` in all): now if the device takes them, else through the queue.

        `out` counts a message once the device took the unit carrying it.
        """
        if not units:
            return
        base, extra = divmod(messages, len(units))  # a frame packing several messages carries each: unit i
        with self._lock:                             # carries base + (i < extra)
            done = 0
            if not (self._busy or self._queue or self._rest is not None):
                write_nowait = self._write_nowait
                sent = 0
                for unit in units:
                    count = base + (done < extra)
                    done += 1
                    try:
                        rest = write_nowait(unit)
                    except Exception:  # a transport that broke its promise not to raise: count, carry on
                        self.link.counters["drop_write_error"] += count
                        continue
                    if rest is not None:  # the device is full: the rest of this unit waits, then the others
                        self._rest = (rest, count)
                        break
                    sent += count
                self.link.counters["out"] += sent
            if done == len(units) and self._rest is None:
                return
            self._enqueue(units[done:], [base + (i < extra) for i in range(done, len(units))])
            self.idle = False
            self._start()
            self._cond.notify()

    def _enqueue(self, units: list[Any], carried: list[int]) -> None:
        queue = self._queue
        for entry in zip(units, carried, strict=True):
            queue.append(entry)
            self._queued += entry[1]
        dropped = 0
        while self._queued > self.limit and len(queue) > 1:
            _unit, count = queue.popleft()
            self._queued -= count
            dropped += count
        if dropped:
            self.link.counters["tx_overflow"] += dropped
            self._tell_stall()
            self._dropped_in_episode += dropped

    def _start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._drain, name=f"write-{self.link.name}", daemon=True)
            self._thread.start()

    def _drain(self) -> None:
        cond = self._cond
        while True:
            with cond:
                while not self._queue and self._rest is None and not self._closing:
                    cond.wait()
                # a unit is counted as in the write before it leaves the queue: `room` reads without the lock
                if self._rest is not None:
                    unit, count = self._rest
                    self._writing = count
                    self._rest = None
                elif self._queue:
                    unit, count = self._queue[0]
                    self._writing = count
                    self._queue.popleft()
                    self._queued -= count
                else:
                    return  # closing, and nothing left
                self._busy = True
            try:
                self._write(unit)  # one unit at a time: the oldest stays droppable while the device is stuck
            except Exception:  # a transport that broke its promise not to raise: count, keep the thread alive
                self.link.counters["drop_write_error"] += count
            else:
                self.link.counters["out"] += count
            with cond:
                self._busy = False
                self._writing = 0
                room_again = self._full and self._queued < self.hold
                if room_again:
                    self._full = False
                if not self._queue and self._rest is None:
                    self.idle = True
                    if self._told:
                        log.warning("%s: the device takes what we send again (%d messages dropped meanwhile: "
                                    "tx_overflow)", self.link.name, self._dropped_in_episode)
                    self._told, self._full_since, self._dropped_in_episode = False, None, 0
                    cond.notify_all()
            if room_again and self._on_room is not None:
                self._on_room()

    def close(self, wait: float = CLOSE_WAIT) -> None:
        """Give the device up to `wait` seconds to take what is queued, then stop; what is left is counted."""
        deadline = time.monotonic() + wait
        with self._cond:
            while (self._queue or self._rest is not None or self._busy) and self._thread is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._cond.wait(left)
            if self._queued:
                self.link.counters["unsent_at_close"] += self._queued
            self._queue.clear()
            self._queued = 0
            self._rest = None
            self._closing = True
            self._cond.notify_all()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=wait)
