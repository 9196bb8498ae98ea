"""What a Node sends, in what order: the engine's outbox onto each link's outlet, then each outlet's flush.

C twin: vstig_hw/_cext/path.c (its spread after a batch; index: vstig_hw/_vstig.pyi).

`spread` runs under the Node's lock, after a batch (on the reader's thread), a
caller's put/get/ask, and every step of the loop. It tells the loop, through the
DeliveryState's `retry_at`, when a budget window next lets held-back messages out.
"""

from __future__ import annotations

import time

from ..wire import Message
from .delivery_state import DeliveryState
from .outlet import Outlet
from .parts import Seat

__all__ = ["Outbound"]

Marks = list[tuple[Outlet, int]]  # each outlet, and how many it will have handed on once what it holds now left


class Outbound:
    """The outlets (`outlets[i]` is `links[i]`'s), the order they flush in, and what a stop drains."""

    def __init__(self, outlets: list[Outlet], seat: Seat | None, state: DeliveryState) -> None:
        self.outlets = outlets
        self.seat = seat  # whose outbox goes out first (None: a relay's or a listener's, nothing queued here)
        self._state = state
        self._flush_order: dict[int, list[Outlet]] = {}  # heard_on -> the outlets in `spread`'s order

    def spread(self, now: float, heard_on: int = 0) -> None:
        """Queue the engine's outbox on the links (`Seat.queue_out`), then send what budgets allow.

        Links that just delivered (bits of `heard_on`) are flushed last: on a broadcast
        medium every robot there heard those frames when we did, so what they caused is
        news on the other links first, and a slow echo must not hold up the crossing.
        """
        if self.seat is not None:
            self.seat.queue_out()
        outlets = self.outlets
        if heard_on:
            outlets = self._flush_order.get(heard_on) or self._order_for(heard_on)
        retry = None
        for outlet in outlets:
            again = outlet.flush(now)
            if again is not None and (retry is None or again < retry):
                retry = again
        self._state.retry_at = retry

    def spread_and_wake(self) -> None:
        """`spread` for a caller's put/get/ask: a waiting loop must look again if a budget held some back."""
        self.spread(time.monotonic())
        state = self._state
        retry = state.retry_at
        if retry is not None and retry < state.sleep_until:
            state.wake.set()

    def _order_for(self, heard_on: int) -> list[Outlet]:
        """The outlets with those of links in `heard_on` last, the others in their order (a stable sort)."""
        outlets = self.outlets
        order = [outlets[i] for i in sorted(range(len(outlets)), key=lambda i: heard_on >> i & 1)]
        self._flush_order[heard_on] = order
        return order

    def send_now(self, message: Message) -> None:
        """`message` on every link at once, ahead of whatever is queued or held back by a budget window."""
        now = time.monotonic()
        for outlet in self.outlets:
            outlet.send_now(message, now)

    def marks(self) -> Marks:
        """What `drained` compares against: each outlet's count once what it holds now has left."""
        return [(outlet, outlet.handed + len(outlet)) for outlet in self.outlets]

    @staticmethod
    def drained(marks: Marks) -> bool:
        """Whether what the outlets held at `marks` has left them and their writers."""
        return all((not len(outlet) or outlet.handed >= mark) and not len(outlet.writer) for outlet, mark in marks)

    def queued(self) -> dict[str, int]:
        """Per link name, the messages its outlet and writer still hold (links holding none left out)."""
        return {outlet.link.name: len(outlet) + len(outlet.writer) for outlet in self.outlets
                if len(outlet) or len(outlet.writer)}

    def close(self, deadline: float) -> None:
        """The devices get until `deadline` to take what the writers hold; what is left is counted."""
        for outlet in self.outlets:
            outlet.close(max(0.0, deadline - time.monotonic()))
