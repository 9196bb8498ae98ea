"""Each write's spread through the swarm, measured live, by `analyze`'s definitions.

`analyze` (vstig_hw.analysis) measures a finished capture; this follows the same
writes while they spread, for the live view: a *write* is a new (key, timestamp,
robot) entry; a sender *caught up* the first time one of its messages showed the
write or a newer entry for the key (`newer`: a higher timestamp, or the same one
and the conflict winner); its *active senders* are those heard within `window`
seconds either side of its first appearance, to a resolution of window/8, of
which, live, only the part heard so far is known. Pure Python (no numpy): the
live view runs on the core install plus its own extra.

Bounded: it follows the `keep` newest writes; older ones are forgotten (counted in
`forgotten`), as is a sender's activity older than the window.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

from ..links.link import Heard
from ..timestamps import TS_NONE, is_newer

__all__ = ["LiveSpread", "WriteSpread"]

DEFAULT_KEEP = 1024  # writes followed at once
DEFAULT_WINDOW = 10.0  # analyze's (vstig_hw.analysis.DEFAULT_WINDOW; that module needs numpy): a test holds them equal


@dataclass
class WriteSpread:
    key: int
    value: int
    timestamp: int
    robot: int
    t: float  # first appearance, on any link
    link: str  # where it first appeared
    caught_up: dict[int, float] = field(default_factory=dict)  # sender -> seconds after `t` it showed it or newer
    superseded: bool = False  # a newer entry for the key has appeared


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
        self._writes: OrderedDict[tuple[int, int, int], WriteSpread] = OrderedDict()  # oldest first
        self._by_key: dict[int, list[WriteSpread]] = {}
        self._activity: dict[int, set[int]] = {}  # sender -> the window/8 slots it was heard in
        self._changed: dict[tuple[int, int, int], WriteSpread] = {}

    def add(self, heard: Heard) -> None:
        msg, sender, t = heard.message, heard.sender, heard.t
        if sender is not None:
            self._activity.setdefault(sender, set()).add(math.floor(t / self._slot))
        if msg.timestamp == TS_NONE:
            return  # an empty GET: no entry to show
        key = msg.key
        code = (key, msg.timestamp, msg.robot)
        shown = (msg.timestamp, msg.robot, msg.value)
        if code not in self._writes:
            self._start(code, WriteSpread(key, msg.value, msg.timestamp, msg.robot, t, heard.link), shown)
        if sender is None:
            return
        for write in self._by_key.get(key, ()):
            if sender not in write.caught_up and (
                    shown[:2] == (write.timestamp, write.robot) or self._newer(shown, write)):
                write.caught_up[sender] = max(0.0, t - write.t)
                self._changed[(write.key, write.timestamp, write.robot)] = write

    def _start(self, code: tuple[int, int, int], write: WriteSpread, shown: tuple[int, int, int]) -> None:
        writes = self._writes
        writes[code] = write
        family = self._by_key.setdefault(write.key, [])
        for older in family:
            if self._newer(shown, older):
                older.superseded = True
        family.append(write)
        self._changed[code] = write
        while len(writes) > self.keep:
            _, old = writes.popitem(last=False)
            self._by_key[old.key].remove(old)
            if not self._by_key[old.key]:
                del self._by_key[old.key]
            self._changed.pop((old.key, old.timestamp, old.robot), None)
            self.forgotten += 1

    def _newer(self, entry: tuple[int, int, int], write: WriteSpread) -> bool:
        """Entry (timestamp, robot, value) is newer than the write."""
        if entry[0] != write.timestamp:
            return is_newer(entry[0], write.timestamp)
        if self.larger_value_wins:
            return (entry[2], entry[1]) > (write.value, write.robot)
        return entry[1] > write.robot

    def active(self, write: WriteSpread) -> list[int]:
        """The senders heard so far within the window either side of the write's first appearance."""
        low = math.floor((write.t - self.window) / self._slot)
        high = math.floor((write.t + self.window) / self._slot)
        return sorted(s for s, slots in self._activity.items() if any(low <= slot <= high for slot in slots))

    def forget_before(self, now: float) -> None:
        """Drop activity no write still followed can need (older than the oldest write's window)."""
        oldest = next(iter(self._writes.values())).t if self._writes else now
        floor = math.floor((min(oldest, now) - self.window) / self._slot)
        for sender in list(self._activity):
            slots = {slot for slot in self._activity[sender] if slot >= floor}
            if slots:
                self._activity[sender] = slots
            else:
                del self._activity[sender]

    def row(self, write: WriteSpread, now: float) -> dict[str, Any]:
        """The write as the live view shows it: who caught up, who is behind, and for how long so far."""
        active = self.active(write)
        behind = [s for s in active if s not in write.caught_up]
        caught = sorted(write.caught_up.get(s, 0.0) for s in active if s in write.caught_up)
        converged = bool(active) and not behind
        return {"key": write.key, "value": write.value, "timestamp": write.timestamp, "robot": write.robot,
                "first_heard": write.t, "link": write.link, "senders_total": len(active),
                "senders_caught_up": len(caught), "behind": behind,
                "time_so_far": round(max(0.0, now - write.t), 6),
                "converged_after": round(caught[-1], 6) if converged else None,
                "superseded": write.superseded}

    def updates(self, now: float, limit: int) -> list[dict[str, Any]]:
        """Rows of the writes that changed since the last call, then of those still spreading within their
        window (their time so far grows), newest first: at most `limit`."""
        rows = [self.row(w, now) for w in reversed(self._changed.values())][:limit]
        self._changed.clear()
        if len(rows) < limit:
            seen = {(r["key"], r["timestamp"], r["robot"]) for r in rows}
            for code, write in reversed(self._writes.items()):
                if len(rows) >= limit or now - write.t > self.window:
                    break
                if code in seen or write.superseded:
                    continue
                row = self.row(write, now)
                if row["converged_after"] is None:
                    rows.append(row)
        return rows
