"""Clock offsets between gateways, the way NTP measures them, sans I/O: a round trip gives a bound, not a guess.

We ask a peer for its time at `sent` (our clock) and hear it at `received`; the peer read its clock at some
moment between the two, so its clock minus ours is `peer_time - (sent + received) / 2`, give or take half the
round trip. Of the last WINDOW round trips to a peer the one with the shortest delay is kept (NTP's clock
filter, reduced to its core): queueing only ever lengthens a round trip, so the shortest is the tightest bound.

A process is one clock (a faketime'd process is its own), named by CLOCK_ID, made once per process.
"""

from __future__ import annotations

import collections
import uuid
from dataclasses import dataclass

__all__ = ["CLOCK_ID", "WINDOW", "ClockOffset", "OffsetFilter", "measure"]

CLOCK_ID = uuid.uuid4().hex[:16]  # this process's clock: captures name it, peers answer for theirs
WINDOW = 8  # round trips a peer's estimate is chosen from


@dataclass(frozen=True, slots=True)
class ClockOffset:
    peer: str  # the peer's CLOCK_ID
    offset: float  # seconds: the peer's clock minus ours
    error: float  # seconds: the true offset is within offset ± error
    at: float  # our clock when it was measured (the round trip's end)


def measure(peer: str, sent: float, peer_time: float, received: float) -> ClockOffset:
    """One round trip's offset and its bound; a reply heard before it was asked for is impossible (ValueError)."""
    if received < sent:
        raise ValueError(f"a round trip cannot end ({received}) before it starts ({sent})")
    return ClockOffset(peer, peer_time - (sent + received) / 2, (received - sent) / 2, received)


class OffsetFilter:
    """Per peer, the tightest of its last WINDOW round trips."""

    def __init__(self, window: int = WINDOW) -> None:
        self.window = window
        self._trips: dict[str, collections.deque[ClockOffset]] = {}

    def add(self, sample: ClockOffset) -> ClockOffset:
        """Take one round trip; the peer's estimate now."""
        trips = self._trips.setdefault(sample.peer, collections.deque(maxlen=self.window))
        trips.append(sample)
        return min(trips, key=lambda trip: trip.error)

    def estimates(self) -> dict[str, ClockOffset]:
        return {peer: min(trips, key=lambda trip: trip.error) for peer, trips in self._trips.items()}
