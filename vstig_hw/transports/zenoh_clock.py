"""Clock round trips between Zenoh sessions, over the session a link already has (vstig_hw.clocks does the
arithmetic).

Every session answers queries on `vstig/<swarm>/clock/<CLOCK_ID>` with its wall clock (nanoseconds, decimal
text), and asks `vstig/<swarm>/clock/*` every PROBE_EVERY_S from the transport's read thread; replies are
measured on Zenoh's thread as they come. Nothing here touches the swarm's samples: the clock keys are outside
the stigmergies' `vstig/<swarm>/<n>/*` (firmware_spec/SPEC.md, "Zenoh").
"""

from __future__ import annotations

import collections
import threading
import time
from typing import Any

import zenoh

from ..clocks import CLOCK_ID, ClockOffset, OffsetFilter, measure

__all__ = ["PROBE_EVERY_S", "ZenohClock"]

PROBE_EVERY_S = 2.0  # a round trip to every peer this often: a few dozen bytes each
_REPLY_WAIT_S = 1.0  # a reply later than this bounds nothing useful
_KEPT = 256  # measurements waiting for `take` (a recorder takes them every tick)


class ZenohClock:
    def __init__(self, prefix: str) -> None:
        self.prefix = prefix  # vstig/<swarm>/clock
        self.filter = OffsetFilter()
        self._queryable: Any = None
        self._next_probe = 0.0
        self._lock = threading.Lock()  # replies come on Zenoh's threads
        self._new: collections.deque[ClockOffset] = collections.deque(maxlen=_KEPT)

    def attach(self, session: zenoh.Session) -> None:
        """Answer for this process's clock on `session`."""
        key = f"{self.prefix}/{CLOCK_ID}"

        def answer(query: zenoh.Query) -> None:  # under our own key: the asker learns whose clock it read
            query.reply(key, str(time.time_ns()))

        self._queryable = session.declare_queryable(key, answer)

    def detach(self) -> None:
        self._queryable = None  # undeclared with its session

    def probe(self, session: zenoh.Session) -> None:
        """Ask every peer for its time, if a round is due; on the transport's read thread."""
        now = time.monotonic()
        if now < self._next_probe:
            return
        self._next_probe = now + PROBE_EVERY_S
        sent = time.time()
        try:
            session.get(f"{self.prefix}/*", lambda reply: self._reply(reply, sent), timeout=_REPLY_WAIT_S)
        except zenoh.ZError:  # the session is closing: the next round asks again
            return

    def _reply(self, reply: zenoh.Reply, sent: float) -> None:
        received = time.time()
        sample = reply.ok
        if sample is None:
            return
        peer = str(sample.key_expr).rsplit("/", 1)[-1]
        if peer == CLOCK_ID:  # our own answer (another link of this process)
            return
        try:
            peer_time = int(sample.payload.to_bytes()) / 1e9
            trip = measure(peer, sent, peer_time, received)
        except ValueError:  # not a clock's answer
            return
        with self._lock:
            self.filter.add(trip)
            self._new.append(trip)

    def estimates(self) -> dict[str, ClockOffset]:
        """Each peer's offset now (the tightest of its recent round trips)."""
        with self._lock:
            return self.filter.estimates()

    def take(self) -> list[ClockOffset]:
        """The round trips measured since the last call."""
        with self._lock:
            new = list(self._new)
            self._new.clear()
        return new
