"""Clock offsets between gateways, the way NTP measures them, sans I/O: a round trip gives a bound, not a guess.

We ask a peer for its time at `sent` (our clock) and hear it at `received`; the peer read its clock at some
moment between the two, so its clock minus ours is `peer_time - (sent + received) / 2`, give or take half the
round trip. Of the last WINDOW round trips to a peer the one with the shortest delay is kept (NTP's clock
filter, reduced to its core): queueing only ever lengthens a round trip, so the shortest is the tightest bound.

A process is one clock (a faketime'd process is its own), named by CLOCK_ID, made once per process.

Who answered matters (DECISIONS.md, "Clocks by round trips over Zenoh"): a round trip keeps the name of the
certificate that proved the answering session (`proof`), or None where nothing proved it; the filter keeps the
two apart, so unproved answers under a peer's id never stand in for its proved ones. It tracks MAX_PEERS clocks
at most, whoever claims ids: more are refused (`add` returns None), for the caller to count.
"""

from __future__ import annotations

import collections
import uuid
from dataclasses import dataclass

__all__ = ["CLOCK_ID", "CLOCK_ID_LENGTH", "MAX_PEERS", "MAX_PROOF_CHARS", "STALE_S", "WINDOW", "ClockOffset",
           "OffsetFilter", "measure"]

CLOCK_ID = uuid.uuid4().hex[:16]  # this process's clock: captures name it, peers answer for theirs
CLOCK_ID_LENGTH = len(CLOCK_ID)  # hex digits
WINDOW = 8  # round trips a peer's estimate is chosen from
MAX_PEERS = 64  # clocks tracked per link (proved and unproved apart): a swarm's gateways, not a flood's made-up ids
STALE_S = 60.0  # a clock not heard from for this long gives its place up to a new one
MAX_PROOF_CHARS = 128  # a certificate name as kept (percent-encoded): enough for any lab's naming


@dataclass(frozen=True, slots=True)
class ClockOffset:
    peer: str  # the peer's CLOCK_ID
    offset: float  # seconds: the peer's clock minus ours
    error: float  # seconds: the true offset is within offset ± error
    at: float  # our clock when it was measured (the round trip's end)
    proof: str | None = None  # the certificate name the transport proved the answering session holds; None: unproved


def measure(peer: str, sent: float, peer_time: float, received: float, proof: str | None = None) -> ClockOffset:
    """One round trip's offset and its bound; a reply heard before it was asked for is impossible (ValueError)."""
    if received < sent:
        raise ValueError(f"a round trip cannot end ({received}) before it starts ({sent})")
    return ClockOffset(peer, peer_time - (sent + received) / 2, (received - sent) / 2, received, proof)


def _tightest(trips: collections.deque[ClockOffset]) -> ClockOffset:
    return min(trips, key=lambda trip: trip.error)


class OffsetFilter:
    """Per peer (its proved and unproved answers apart), the tightest of its last WINDOW round trips; `peers` of
    them at most. A full filter makes room for a newcomer only by dropping a peer not heard for STALE_S or, for a
    proved newcomer, the unproved peer heard longest ago: ids a flood makes up cannot push a proved peer out."""

    def __init__(self, window: int = WINDOW, peers: int = MAX_PEERS) -> None:
        self.window = window
        self.peers = peers
        self._trips: dict[tuple[str, str | None], collections.deque[ClockOffset]] = {}

    def add(self, sample: ClockOffset) -> ClockOffset | None:
        """Take one round trip; the peer's estimate now, or None if the filter is full of other peers."""
        key = (sample.peer, sample.proof)
        trips = self._trips.get(key)
        if trips is None:
            if len(self._trips) >= self.peers and not self._make_room(sample):
                return None
            trips = self._trips[key] = collections.deque(maxlen=self.window)
        trips.append(sample)
        return _tightest(trips)

    def _make_room(self, newcomer: ClockOffset) -> bool:
        def last_heard(key: tuple[str, str | None]) -> float:
            return self._trips[key][-1].at

        quiet = min(self._trips, key=last_heard)
        if newcomer.at - last_heard(quiet) <= STALE_S:  # none stale: only an unproved peer yields, to a proved one
            unproved = [key for key in self._trips if key[1] is None]
            if newcomer.proof is None or not unproved:
                return False
            quiet = min(unproved, key=last_heard)
        del self._trips[quiet]
        return True

    def estimates(self) -> list[ClockOffset]:
        """Each peer's estimate: its proved one and its unproved one apart."""
        return [_tightest(trips) for trips in self._trips.values()]
