"""BittyBuzz's 8-bit Lamport clock against our 16-bit timestamps, one anchor per key.

A Kilobot takes a message as newer when its lamport is 1 to 49 steps ahead of its
own, modulo 256 (BittyBuzz bbzmsg.c `bbzlamport_isnewer`, BBZLAMPORT_THRESHOLD 50).
Our timestamps are 16-bit and compared by serial arithmetic. Neither clock can be
computed from the other, so the bridge keeps, per key, an *anchor*: the latest
version both sides know, as (our timestamp, Kilobot lamport, value, writer).

- From the Kilobots, lamport L is d = (L - anchor) mod 256 steps ahead:
  d in 1..49 is news, and becomes our timestamp anchor + d; d = 0 with the same
  value is a repeat (the echo storm of pre-2021 firmware, or a query reply that
  carries the replier's id); d = 0 with another value is the Kilobots' own
  conflict, which their rule gives to the higher robot id: if that is the new
  writer we pass it on as a new version (anchor + 1), so our side never sees one
  timestamp with two values; d >= 50 means that robot is behind (or missed our
  last version), and a losing conflict means it holds a version that lost: both
  are answered with the anchor's version at that robot's lamport + 1, the one
  step its window accepts.
- Toward the Kilobots, a version newer than the anchor (or the anchor's
  timestamp with another value, after our side settled a conflict) goes out at
  the anchor's lamport + 1: one step, never a jump of 50 or more, never an
  already-used lamport with another value.

Before the first exchange on a key the two clocks are taken as equal modulo 256
(our timestamp T is sent as lamport T mod 256, lamport L arrives as timestamp L),
so robots that all put at timestamp 1 meet in one conflict, as on one medium.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ..timestamps import TS_MAX, is_newer

__all__ = ["BBZ_LAMPORT_THRESHOLD", "Anchor", "LamportBridge", "Verdict", "advance", "bbz_is_newer"]

BBZ_LAMPORT_THRESHOLD = 50


def bbz_is_newer(lamport: int, old: int, threshold: int = BBZ_LAMPORT_THRESHOLD) -> bool:
    """BittyBuzz's rule since 42cd16d (2021): 1..threshold-1 steps ahead, modulo 256."""
    return lamport != old and (lamport - old) & 0xFF < threshold


def advance(timestamp: int, steps: int) -> int:
    """Our timestamp `steps` versions later, skipping the reserved 0 when it wraps."""
    moved = timestamp + steps
    return moved if moved <= TS_MAX else moved - TS_MAX


class Verdict(enum.Enum):
    """What the bridge made of one Kilobot message (the name is the drop counter when nothing passes)."""

    NEWER = "newer"
    REPEAT = "bbz_repeat"
    CONFLICT_LOST = "bbz_conflict_lost"
    STALE = "bbz_stale"


@dataclass(frozen=True)
class Anchor:
    timestamp: int
    lamport: int
    value: tuple[int, int]  # as the Kilobots hold it: (type tag, 16 bits)
    robot: int


class LamportBridge:
    """Per-key anchors; `from_kilobots` and `to_kilobots` translate one version each way."""

    def __init__(self, threshold: int = BBZ_LAMPORT_THRESHOLD) -> None:
        if not 1 <= threshold <= 255:
            raise ValueError(f"the lamport threshold must be in 1..255, got {threshold}")
        self.threshold = threshold
        self.anchors: dict[int, Anchor] = {}

    def from_kilobots(self, key: int, lamport: int, value: tuple[int, int], robot: int) -> tuple[Verdict, Anchor]:
        """(verdict, the key's anchor after it).

        NEWER: the anchor's timestamp is the version to hand our side. STALE and
        CONFLICT_LOST: the Kilobot that sent this holds a losing version, so the anchor
        moves to the lamport right after it, and the anchor is the reply that repairs
        that robot (one step ahead of what it showed, as the window requires).
        """
        anchor = self.anchors.get(key)
        if anchor is None:
            timestamp = lamport or 0x100  # lamport 0 after a wrap: 256 versions in, never our reserved 0
        else:
            steps = (lamport - anchor.lamport) & 0xFF
            if steps == 0 and value == anchor.value:
                return Verdict.REPEAT, anchor
            if steps >= self.threshold or (steps == 0 and robot < anchor.robot):
                repaired = Anchor(anchor.timestamp, (lamport + 1) & 0xFF, anchor.value, anchor.robot)
                self.anchors[key] = repaired
                return (Verdict.STALE if steps else Verdict.CONFLICT_LOST), repaired
            timestamp = advance(anchor.timestamp, steps or 1)
        self.anchors[key] = Anchor(timestamp, lamport, value, robot)
        return Verdict.NEWER, self.anchors[key]

    def to_kilobots(self, key: int, timestamp: int, value: tuple[int, int], robot: int) -> int | None:
        """The lamport to send our version at, or None when the Kilobots already hold it or newer."""
        anchor = self.anchors.get(key)
        if anchor is None:
            lamport = timestamp & 0xFF or 1
        elif is_newer(timestamp, anchor.timestamp) or (timestamp == anchor.timestamp and value != anchor.value):
            lamport = (anchor.lamport + 1) & 0xFF
        else:
            return None
        self.anchors[key] = Anchor(timestamp, lamport, value, robot)
        return lamport
