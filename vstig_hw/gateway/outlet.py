"""One link's way out: a send queue drained under a per-tick budget.

C twin: vstig_hw/_cext/window.c (Window: SendWindow), vstig_hw/_cext/outlet.c (Outlet); held equal by tests/native
(index: vstig_hw/_vstig.pyi).

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

The queue shares the link among the sources of what it carries (`fairshare`): one
line per source, served in turn, so a source that floods waits for its own messages
and every other source's go first. A backlog leaves a reserve of the window unused,
so a sparse source's message (its line was empty) leaves at once, not at the pace.

What leaves the window goes to the link's `LinkWriter`: written at once while the
device takes it, else queued for that link's own thread, so a device that stops
taking data never holds up the loop or another link. The writer holds at most
`WRITER_HOLD` messages the device has not taken; the rest wait here, in their
sources' lines, so the share also decides what a slow device gets next.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable
from typing import Any

from ..counters import Counters
from ..links.link import Link
from ..wire import Message
from .fairshare import LOCAL, FairFifo, FairQueue
from .writer import CLOSE_WAIT, TX_QUEUE_LIMIT, LinkWriter

__all__ = ["Outlet", "SendWindow"]

RAW_QUEUE_LIMIT = 10_000  # raw mode keeps every frame; beyond this a flooder's oldest are dropped and counted


PACE_BURST = 4  # messages a backlog sends at once after a late wake-up (else one per period/(budget - reserve))
RESERVE_SHARE = 16  # a backlog leaves 1/16 of the budget (at least 1 from a budget of 4) to sparse sources


class SendWindow:
    """At most `budget` sends in any `period` seconds (None: unlimited), evenly spaced while a backlog lasts, with
    a reserve kept for sparse sources.

    After a quiet spell a burst leaves at once, up to the budget (`free`). A backlog
    (`allowance`) never uses the last `reserve` places of the window, and while it
    lasts (`record(..., backlog=True)`) its messages leave one every period/(budget -
    reserve) (up to PACE_BURST at once after a late wake-up), not in a burst each
    time the window reopens. A sparse source's message (`fairshare`: its line was
    empty) may use the whole window (`free`) and does not move the backlog's pace
    (`record(..., sparse=True)`): so it leaves at once while another source floods,
    the budget is never exceeded, and the flood gets the rest.
    """

    def __init__(self, budget: int | None, period: float) -> None:
        if budget is not None and budget < 1:
            raise ValueError(f"budget must be at least 1 message per tick, got {budget}")
        if period <= 0:
            raise ValueError(f"the tick period must be positive, got {period}")
        self.budget = budget
        self.period = period
        self.reserve = max(1, budget // RESERVE_SHARE) if budget is not None and budget >= 4 else 0
        self._sent: deque[float] = deque(maxlen=budget or 1)
        self._spacing = period / (budget - self.reserve) if budget else 0.0
        self._paced_to: float | None = None  # while backlogged: the time up to which the pace was spent

    def free(self, now: float) -> int:
        """How many may leave at `now` by the budget alone (a sparse source's message, or a burst after a quiet
        spell)."""
        if self.budget is None:
            return 1 << 30
        sent = self._sent
        while sent and sent[0] <= now - self.period:
            sent.popleft()
        return self.budget - len(sent)

    def allowance(self, now: float) -> int:
        """How many of a backlog may leave at `now`: the budget less the reserve, at the pace."""
        if self.budget is None:
            return 1 << 30
        free = self.free(now) - self.reserve
        if self._paced_to is None:
            return free
        return min(free, PACE_BURST, int((now - self._paced_to) / self._spacing))

    def record(self, now: float, count: int, backlog: bool = False, sparse: bool = False) -> None:
        """`count` messages left at `now`; `backlog`: others still wait (the sends are spaced from now on);
        `sparse`: they were sparse sources' (the backlog's pace stays where it was)."""
        if self.budget is None:
            return
        if count == 1:
            self._sent.append(now)
        else:
            self._sent.extend([now] * min(count, self.budget))
        if not backlog:
            self._paced_to = None
        elif sparse:  # from the reserve: the backlog's pace stays where it was
            return
        elif self._paced_to is None:  # a backlog starts: what just left was the burst
            self._paced_to = now
        else:
            self._paced_to = max(self._paced_to, now - PACE_BURST * self._spacing) + count * self._spacing

    def next_free(self, sparse: bool = False) -> float | None:
        """When the window next lets a message of the backlog go (`sparse`: a sparse source's), if it does not
        now (None: it does, or there is no budget)."""
        if self.budget is None:
            return None
        sent = self._sent
        if sparse:
            return sent[0] + self.period if len(sent) >= self.budget else None
        over = len(sent) - (self.budget - self.reserve)  # the backlog has a place once over + 1 have expired
        opens = sent[over] + self.period if over >= 0 else None
        if self._paced_to is None:
            return opens
        paced = self._paced_to + self._spacing
        return paced if opens is None else max(opens, paced)


class Outlet:
    """A link, its send queue (one line per source: `fairshare`) and its budget window.

    What is pushed while nothing waits is only held (`_held`), as it came, until the
    next flush: if the window and the writer take it all, it goes out as it came
    (what its source's line would have sent, in that order), and only what must
    wait enters the lines. So a gateway that keeps up pays nothing for the share.

    `on_room` is called from the link's writer thread when a device that was slow
    takes data again: what waits here can go (a Node wakes its loop)."""

    def __init__(self, link: Link[Any], budget: int | None, period: float, *, keep_all: bool = False,
                 tx_queue: int = TX_QUEUE_LIMIT, on_room: Callable[[], None] | None = None) -> None:
        self.link = link
        self.writer = LinkWriter(link, tx_queue, on_room=on_room)
        self.window = SendWindow(budget, period)
        self.keep_all = keep_all  # raw mode: every frame kept, in order per source, not newest-per-key
        self.queue: FairQueue | FairFifo = FairFifo(RAW_QUEUE_LIMIT) if keep_all else FairQueue()
        # What a message not queued counts as: a raw queue dropped a flooder's oldest to make room; an engine
        # queue had a message at least as new for its key pending.
        self._not_queued = "drop_overflow" if keep_all else "superseded"
        self._held: list[Message] = []  # one push's messages, pushed while nothing waited: see the docstring
        self._held_link = LOCAL  # and their source
        self._held_sub: Hashable = None
        self._held_ours = False  # `_held` is a list of our own (a raw batch's units joined), not the caller's
        self.handed = 0  # messages handed to the writer so far (what `Node.drain` waits for)

    @property
    def counters(self) -> Counters:
        return self.link.counters

    def __len__(self) -> int:
        return len(self.queue) + len(self._held)

    def push(self, messages: list[Message], link: int = LOCAL, sub: Hashable = None) -> None:
        """Queue `messages` from source (`link`, `sub`): `link` is the index of the link they came from (LOCAL:
        this gateway's own), `sub` tells that link's peers apart where it can (None: the link as one source).
        The list is kept as it is until sent: the caller must not change it."""
        if not messages:
            return
        held = self._held
        if not held:
            if not self.queue.active:  # nothing waits
                self._held, self._held_link, self._held_sub, self._held_ours = messages, link, sub, False
                return
        elif self.keep_all and link == self._held_link and sub == self._held_sub:  # a raw batch's next unit
            if self._held_ours:
                held.extend(messages)
            else:
                self._held, self._held_ours = held + messages, True
            return
        self._enqueue_held()
        self._enqueue(messages, link, sub)

    def _enqueue(self, messages: list[Message], link: int, sub: Hashable) -> None:
        refused = self.queue.push(messages, link, sub)
        if refused:
            self.counters[self._not_queued] += refused

    def _enqueue_held(self) -> None:
        held = self._held
        if held:
            self._held = []
            self._enqueue(held, self._held_link, self._held_sub)

    def flush(self, now: float) -> float | None:
        """Send what the window and the writer's room allow; returns when to try again if messages wait.

        A writer without room calls `on_room` when it has some again: no retry time for that.
        """
        window = self.window
        writer = self.writer
        held = self._held
        if held:  # nothing else waits: all of it now, as it came, if the window and the writer take it all
            room = writer.room()
            if len(held) <= room and (window.budget is None or len(held) <= window.free(now)):
                self._held = []
                window.record(now, len(held))
                self._submit(held)
                return None
            self._enqueue_held()
        queue = self.queue
        while queue.active:
            allowed = writer.room()
            if allowed <= 0:
                return None
            sparse = 0
            if window.budget is not None:
                sparse = len(queue.sparse)  # sparse sources' messages, first in the lines: at once, the budget allowing
                allowed = min(allowed, sparse, window.free(now)) if sparse else min(allowed, window.allowance(now))
                if allowed <= 0:
                    return window.next_free(bool(sparse))
            batch = queue.drain(allowed)
            window.record(now, len(batch), bool(queue.active), bool(sparse))
            self._submit(batch)
        return None

    def _submit(self, batch: list[Message]) -> None:
        self.handed += len(batch)
        try:
            self.writer.submit(self.link.units_of(batch), len(batch))  # one unit for the batch on a byte stream
        except Exception:  # a transport that broke its promise not to raise: count, keep the loop alive
            self.counters["drop_write_error"] += len(batch)

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
        held = len(self)  # left where it is: nothing flushes a closed outlet
        if held:
            self.counters["unsent_at_close"] += held
        self.writer.close(wait)
