"""Clock notes in captures that keep notes (serial, zenoh, MCAP: capture.notes): whose clock a capture's times are, and
that clock's offsets to the other gateways' clocks, so captures made on several PCs merge on one time base.

    # vstig clock 3f2a9c1e5b7d4a60
    # vstig clock-offset (1700000000.250000) 9b1c0d2e3f4a5b6c +0.250012345 0.000412000 cert=gw-b
    # vstig clock-offset (1700000000.250000) 0d2e3f4a5b6c9b1c +1000.000012345 0.000412000 unproved

Comment lines to any reader that does not know them. The first names the recording process's clock
(vstig_hw.clocks.CLOCK_ID); each offset is one round trip to a peer's clock: when it ended (our clock), the
peer, its clock minus ours, the bound (both in seconds), and who answered: `cert=NAME`, the certificate that
proved the answering session, or `unproved` (an offset with neither was recorded before answers were checked:
unproved too). `shifts` finds, for each capture, how far its times are from the first capture's clock, with
the tightest bound any of the captures measured, through proved offsets only unless told to trust every note,
and never through a clock that two certificates answered for (`disputed`).
"""

from __future__ import annotations

import heapq
import re
from collections.abc import Sequence
from dataclasses import dataclass

from ..clocks import CLOCK_ID, MAX_PROOF_CHARS, ClockOffset
from .notes import capture_notes

__all__ = ["UNPROVED", "CaptureClock", "Shift", "clock_note", "disputed", "offset_note", "read_clock_notes",
           "shifts"]

UNPROVED = "unproved"
_CLOCK = re.compile(r"# vstig clock ([0-9a-f]{1,32})\s*\Z")
_OFFSET = re.compile(r"# vstig clock-offset \((\d{1,12}\.\d{1,9})\) ([0-9a-f]{1,32}) ([+-]\d{1,12}\.\d{1,12}) "
                     rf"(\d{{1,12}}\.\d{{1,12}})(?: cert=(\S{{1,{MAX_PROOF_CHARS}}})| {UNPROVED})?\s*\Z")


def clock_note() -> str:
    return f"vstig clock {CLOCK_ID}"


def offset_note(trip: ClockOffset) -> str:
    who = UNPROVED if trip.proof is None else f"cert={trip.proof}"
    return f"vstig clock-offset ({trip.at:.6f}) {trip.peer} {trip.offset:+.9f} {trip.error:.9f} {who}"


@dataclass
class CaptureClock:
    clock: str | None  # the recording process's clock; None: the capture names none
    offsets: list[ClockOffset]


def read_clock_notes(path: str) -> CaptureClock:
    clock, offsets = None, []
    for line in capture_notes(path):
        if not line.startswith("# vstig clock"):
            continue
        if (named := _CLOCK.match(line)) is not None:
            clock = clock or named.group(1)
        elif (trip := _OFFSET.match(line)) is not None:
            at, peer, offset, error, proof = trip.groups()
            offsets.append(ClockOffset(peer, float(offset), float(error), float(at), proof))
    return CaptureClock(clock, offsets)


@dataclass(frozen=True)
class Shift:
    """How a capture's times map onto the reference capture's clock: subtract `seconds` (± `error`)."""

    seconds: float
    error: float


def disputed(clocks: Sequence[CaptureClock]) -> dict[str, list[str]]:
    """The clocks that proved offsets say more than one certificate answered for: each with those names."""
    names: dict[str, set[str]] = {}
    for capture in clocks:
        for trip in capture.offsets:
            if trip.proof is not None:
                names.setdefault(trip.peer, set()).add(trip.proof)
    return {clock: sorted(proofs) for clock, proofs in names.items() if len(proofs) > 1}


def shifts(clocks: Sequence[CaptureClock], *, trust_unproved: bool = False) -> list[Shift | None]:
    """Per capture, its shift onto the first capture's clock: 0 for the first (and any capture on the same
    clock), None where no chain of round trips joins the two clocks (that capture stays on its own clock).

    Every capture's round trips are edges between clocks (the tightest per pair, either way round); a capture's
    shift is the sum along the chain whose bounds add up least: two recorders that each measured the same
    gateway (a hub they both connect to) are joined through it. Only proved round trips are edges, and none to
    a disputed clock, unless `trust_unproved`: then every note is.
    """
    edges: dict[str, dict[str, tuple[float, float]]] = {}  # a -> b: (b's clock minus a's, bound)
    doubtful = set() if trust_unproved else set(disputed(clocks))
    for capture in clocks:
        mine = capture.clock
        if mine is None:
            continue
        for trip in capture.offsets:
            if not trust_unproved and (trip.proof is None or trip.peer in doubtful):
                continue
            for a, b, offset in ((mine, trip.peer, trip.offset), (trip.peer, mine, -trip.offset)):
                known = edges.setdefault(a, {}).get(b)
                if known is None or trip.error < known[1]:
                    edges[a][b] = (offset, trip.error)
    reference = clocks[0].clock if clocks else None
    best: dict[str, tuple[float, float]] = {}
    if reference is not None:
        best[reference] = (0.0, 0.0)
        queue = [(0.0, reference)]
        while queue:  # Dijkstra by bound: clocks are few
            error, clock = heapq.heappop(queue)
            if error > best[clock][1]:
                continue
            for peer, (step, step_error) in edges.get(clock, {}).items():
                total = error + step_error
                if peer not in best or total < best[peer][1]:
                    best[peer] = (best[clock][0] + step, total)
                    heapq.heappush(queue, (total, peer))
    out: list[Shift | None] = []
    for index, capture in enumerate(clocks):
        if capture.clock is not None and capture.clock in best:
            out.append(Shift(*best[capture.clock]))
        else:
            out.append(Shift(0.0, 0.0) if index == 0 else None)
    return out
