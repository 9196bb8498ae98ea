"""Each write's spread through the swarm, measured live, by `analyze`'s definitions.

`analyze` (vstig_hw.analysis) measures a finished capture; this follows the same
writes while they spread, for the live view: a *write* is a new (key, timestamp,
robot) entry; a sender *caught up* the first time one of its messages showed the
write or a newer entry for the key (`newer`: a higher timestamp, or the same one
and the conflict winner); its *active senders* are those heard within `window`
seconds either side of its first appearance, to a resolution of window/8, of
which, live, only the part heard so far is known. Pure Python (no numpy): the
live view runs on the core install plus its own extra.

Live, only the newest write of each key is followed: once a newer one appears the
older is *superseded*, its row final (every sender showing the newer entry would
count as caught up on it; `analyze` still says when). That keeps the cost per
message to a few dictionary look-ups, however busy the swarm. Bounded: the `keep`
keys written most recently are followed (older ones counted in `forgotten`), and
activity older than the window is dropped by `forget_before`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ..links.link import Heard
from ..timestamps import TS_NONE, is_newer
from ..wire import Message

__all__ = ["DEFAULT_WINDOW", "LiveSpread", "WriteSpread"]

DEFAULT_KEEP = 4096  # keys whose newest write is followed at once
DEFAULT_WINDOW = 10.0  # analyze's (vstig_hw.analysis.DEFAULT_WINDOW; that module needs numpy): a test holds them equal

Code = tuple[int, int, int]  # key, timestamp, robot


@dataclass
class WriteSpread:
    key: int
    value: int
    timestamp: int
    robot: int
    t: float  # first appearance, on any link
    link: str  # where it first appeared
    caught_up: dict[int, float] = field(default_factory=dict)  # sender -> seconds after `t` it showed it or newer
    superseded: bool = False  # a newer entry for the key has appeared: this row is final

    @property
    def code(self) -> Code:
        return self.key, self.timestamp, self.robot


class LiveSpread:
    def __init__(self, window: float = DEFAULT_WINDOW, larger_value_wins: bool = False,
                 keep: int = DEFAULT_KEEP) -> None:
        if not (math.isfinite(window) and window > 0):
            raise ValueError(f"window must be a positive number of seconds, got {window}")
        self.window = window
        self.larger_value_wins = larger_value_wins
        self.keep = keep
        self.forgotten = 0
        self._slot = window / 8
        self._newest: dict[int, WriteSpread] = {}  # key -> its newest write; oldest first appearance first
        self._activity: dict[int, set[int]] = {}  # sender -> the window/8 slots it was heard in
        self._changed: dict[Code, WriteSpread] = {}

    def add(self, heard: Heard) -> None:
        self.add_message(heard.message, heard.link, heard.t, heard.sender)

    def add_message(self, msg: Message, link: str, t: float, sender: int | None) -> None:
        if sender is not None:
            slot = math.floor(t / self._slot)
            slots = self._activity.get(sender)
            if slots is None:
                self._activity[sender] = {slot}
            elif slot not in slots:
                slots.add(slot)
        timestamp = msg.timestamp
        if timestamp == TS_NONE:
            return  # an empty GET: no entry to show
        key, robot = msg.key, msg.robot
        write = self._newest.get(key)
        if write is None or ((timestamp != write.timestamp or robot != write.robot) and \
                self._newer(timestamp, robot, msg.value, write)):
            if write is not None:  # its final row; the sender showing the newer entry is caught up on it too
                write.superseded = True
                if sender is not None and sender not in write.caught_up:
                    write.caught_up[sender] = max(0.0, t - write.t)
                self._changed[write.code] = write
                del self._newest[key]  # re-inserted last: the dict stays in order of first appearance
            write = self._newest[key] = WriteSpread(key, msg.value, timestamp, robot, t, link)
            self._changed[write.code] = write
            if len(self._newest) > self.keep:
                oldest = next(iter(self._newest.values()))
                del self._newest[oldest.key]
                self._changed.pop(oldest.code, None)
                self.forgotten += 1
        elif timestamp != write.timestamp or robot != write.robot:
            return  # an older entry: its sender has not caught up
        if sender is not None and sender not in write.caught_up:
            write.caught_up[sender] = max(0.0, t - write.t)
            self._changed[write.code] = write

    def _newer(self, timestamp: int, robot: int, value: int, write: WriteSpread) -> bool:
        """Entry (timestamp, robot, value) is newer than the write's."""
        if timestamp != write.timestamp:
            return is_newer(timestamp, write.timestamp)
        if self.larger_value_wins:
            return (value, robot) > (write.value, write.robot)
        return robot > write.robot

    def active(self, write: WriteSpread) -> list[int]:
        """The senders heard so far within the window either side of the write's first appearance."""
        low = math.floor((write.t - self.window) / self._slot)
        high = math.floor((write.t + self.window) / self._slot)
        return sorted(s for s, slots in self._activity.items() if any(low <= slot <= high for slot in slots))

    def forget_before(self, now: float) -> None:
        """Drop activity no write still followed can need (older than the oldest write's window)."""
        oldest = next(iter(self._newest.values())).t if self._newest else now
        floor = math.floor((min(oldest, now) - self.window) / self._slot)
        for sender in list(self._activity):
            slots = {slot for slot in self._activity[sender] if slot >= floor}
            if slots:
                self._activity[sender] = slots
            else:
                del self._activity[sender]

    def row(self, write: WriteSpread, now: float, active: list[int] | None = None) -> dict[str, Any]:
        """The write as the live view shows it: who caught up, who is behind, and for how long so far."""
        if active is None:
            active = self.active(write)
        behind = [s for s in active if s not in write.caught_up]
        caught = sorted(write.caught_up[s] for s in active if s in write.caught_up)
        converged = bool(active) and not behind
        return {"key": write.key, "value": write.value, "timestamp": write.timestamp, "robot": write.robot,
                "first_heard": write.t, "link": write.link, "senders_total": len(active),
                "senders_caught_up": len(caught), "behind": behind,
                "time_so_far": round(max(0.0, now - write.t), 6),
                "converged_after": round(caught[-1], 6) if converged else None,
                "superseded": write.superseded}

    def updates(self, now: float, limit: int) -> list[dict[str, Any]]:
        """Rows of the writes that changed since the last call (newest first), then of those still spreading
        within their window, whose time so far grows: at most `limit`."""
        cache: dict[int, list[int]] = {}  # writes first heard in the same slot have the same active senders

        def row(write: WriteSpread) -> dict[str, Any]:
            slot = math.floor(write.t / self._slot)
            active = cache.get(slot)
            if active is None:
                active = cache[slot] = self.active(write)
            return self.row(write, now, active)

        rows = [row(w) for w in list(reversed(self._changed.values()))[:limit]]
        seen = set(self._changed)
        self._changed.clear()
        for write in reversed(self._newest.values()):
            if len(rows) >= limit or now - write.t > self.window:
                break
            if write.code not in seen:
                shown = row(write)
                if shown["converged_after"] is None:
                    rows.append(shown)
        return rows
