"""The paper's measure on a capture: how long each write takes to reach every robot.

Every message a robot sends carries its view of a key: a PUT relays the entry it
holds, a GET asks with the entry it holds. Where the medium names the sender (a
CAN frame's ID does), a capture therefore tells what every robot believed, and
when. For each write (a new key, timestamp, robot) this module finds when it
first appeared and when each active sender first showed it, or a newer entry for
the key, in one of its own messages.

Pure: no files, no clock. Feed it message columns (`Batch`, or messages one by
one with `add_messages`) in roughly time order; `report()` gives the figures.

Definitions (docs/how-to/analyze.md states them for users):
- *active sender* of a write at time t: a sender heard at some time in
  [t - window, t + window], to a resolution of window/8;
- *newer*: a higher timestamp (serial-number arithmetic, as the engine compares),
  or the same timestamp and the conflict winner by `conflict` ("robot": the
  higher robot id, Buzz's default; "value": the larger value, then robot: the
  paper's Figure 1 rule);
- a sender *caught up* at the first time it showed the write or a newer entry
  (never earlier than the write's first appearance);
- *converged after*: from first appearance until the last active sender caught up.
"""

from __future__ import annotations

import functools
import math
import statistics
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

from .timestamps import TS_NONE, is_newer
from .wire import KEY_MAX, MESSAGE_SIZE, Message

__all__ = ["CONFLICT_RULES", "DEFAULT_WINDOW", "NO_SENDER", "TIMELINE_STEP", "Analyzer", "Batch", "LinkHeard",
           "Report", "Timeline", "Traffic", "WriteReport"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
Conflict = Literal["robot", "value"]
CONFLICT_RULES: tuple[Conflict, ...] = ("robot", "value")
DEFAULT_WINDOW = 10.0  # seconds: 100 of the paper's control steps either side of a write
NO_SENDER = -1  # the medium does not name the sender (serial links)
_ENTRY_BITS = 47  # key (15) | timestamp (16) | robot (16)
_ENTRY_MASK = (1 << _ENTRY_BITS) - 1
_SLOT_ZERO = 1 << 39  # activity slots are stored offset by this, so slots before the origin stay positive
_BATCH = 1 << 16  # messages buffered by add_messages before they are aggregated as one batch
_NEVER = (np.empty(0), np.empty(0, dtype=np.int64))  # the frontier of a sender that never showed the key
_BLOCK = 4096  # writes per block of writes x senders in report()
TIMELINE_STEP = 0.1  # seconds per slot of a link's timeline: the paper's control step
_TIMELINE_PARTS = 64  # batches' slot counts kept apart before they are summed into one
_ON_EDGE = 1e-3  # of a slot: a time stamped k steps in (k x 0.1, rounded in an epoch float) counts in slot k


@dataclass(frozen=True)
class Batch:
    """Messages as columns: time, link index, sender (NO_SENDER if unknown), and the wire fields."""

    t: F64
    link: I64
    sender: I64
    op: I64
    key: I64
    value: I64
    timestamp: I64
    robot: I64

    def __len__(self) -> int:
        return len(self.t)

    def where(self, keep: npt.NDArray[np.bool_]) -> Batch:
        return Batch(self.t[keep], self.link[keep], self.sender[keep], self.op[keep], self.key[keep],
                     self.value[keep], self.timestamp[keep], self.robot[keep])


def _first_last(code: I64, t: F64) -> tuple[list[int], list[int], list[int], list[int]]:
    """Distinct codes, the rows of each one's earliest and latest time, and how many rows each has."""
    if not len(code):
        return [], [], [], []
    order = np.lexsort((t, code))
    ordered = code[order]
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    ends = np.r_[starts[1:] - 1, len(ordered) - 1]
    return ordered[starts].tolist(), order[starts].tolist(), order[ends].tolist(), (ends - starts + 1).tolist()


def _summed(parts: list[tuple[I64, I64]]) -> tuple[I64, I64]:
    """(slots, counts) parts as one: each slot once, ascending, its counts added."""
    slots, inverse = np.unique(np.concatenate([p[0] for p in parts]), return_inverse=True)
    counts = np.bincount(inverse, weights=np.concatenate([p[1] for p in parts]), minlength=len(slots))
    return slots, counts.astype(np.int64)


@dataclass
class Traffic:
    """What one sender or one link put on the air."""

    messages: int = 0
    puts: int = 0
    gets: int = 0

    @property
    def bytes(self) -> int:
        return self.messages * MESSAGE_SIZE


@dataclass(frozen=True)
class Timeline:
    """The messages one link carried per TIMELINE_STEP-wide slot: slot k starts k steps after `start`.

    Sparse (only slots that carried something), so files whose clocks lie years apart cost no memory.
    """

    start: float
    slots: I64  # ascending; may be negative for a file earlier than the first one read
    counts: I64


@dataclass(frozen=True)
class LinkHeard:
    first: float
    last: float
    copies: int


@dataclass(frozen=True)
class WriteReport:
    key: int
    value: int  # raw 16-bit wire value
    timestamp: int
    robot: int
    t: float  # first appearance, on any link
    link: str  # where it first appeared
    senders_total: int  # active senders (0 where no link names senders)
    caught_up_after: tuple[float, ...]  # seconds after `t`, one per active sender that caught up, sorted
    behind: tuple[int, ...]  # active senders that never showed it or newer
    heard: dict[str, LinkHeard]  # per link: first and last time this write was heard
    rank: int  # place among the key's writes from oldest (0) to newest, by timestamp and conflict rule

    @property
    def senders_caught_up(self) -> int:
        return len(self.caught_up_after)

    @property
    def converged_after(self) -> float | None:
        if not self.senders_total or self.behind:
            return None
        return self.caught_up_after[-1]


@dataclass(frozen=True)
class Report:
    start: float | None
    end: float | None
    messages: int
    window: float
    conflict: Conflict
    writes: list[WriteReport]  # in order of first appearance
    links: dict[str, Traffic]
    senders: dict[int, Traffic]
    first_copies: int  # PUTs carrying an entry no PUT had carried before
    rebroadcasts: int  # PUTs repeating an entry already heard in a PUT
    conflicts: int  # writes sharing a key and timestamp with another robot's write
    links_without_sender: list[str] = field(default_factory=list)
    timelines: dict[str, Timeline] = field(default_factory=dict)  # per link, over the whole capture

    @property
    def duration(self) -> float:
        return 0.0 if self.start is None or self.end is None else self.end - self.start

    def convergence(self) -> dict[str, float | int | None]:
        """Median, min, max (and counts) of the writes that reached every active sender."""
        times = sorted(t for w in self.writes if (t := w.converged_after) is not None)
        measured = sum(1 for w in self.writes if w.senders_total)
        return {"writes": len(self.writes), "measured": measured, "converged": len(times),
                "median": statistics.median(times) if times else None,
                "min": times[0] if times else None, "max": times[-1] if times else None}


class Analyzer:
    """Accumulates a capture's messages batch by batch; `report()` computes the measure."""

    def __init__(self, window: float = DEFAULT_WINDOW, conflict: Conflict = "robot") -> None:
        if not (math.isfinite(window) and window > 0):
            raise ValueError(f"window must be a positive number of seconds, got {window}")
        if conflict not in CONFLICT_RULES:
            raise ValueError(f"conflict rule must be one of {', '.join(CONFLICT_RULES)}, got {conflict!r}")
        self.window, self.conflict = window, conflict
        self._slot = window / 8  # activity is kept per slot of this width
        self.links: list[str] = []
        self._link_index: dict[str, int] = {}
        self._start: float | None = None
        self._end: float | None = None
        self._messages = 0
        self._traffic: dict[tuple[int, int, int], int] = defaultdict(int)  # (link, sender, op) -> messages
        self._put_entries: set[int] = set()
        self._puts = 0
        self._writes: dict[int, tuple[float, int, int]] = {}  # entry -> (first t, link, value)
        self._heard: dict[tuple[int, int], list[float]] = {}  # (link, entry) -> [first, last, copies]
        self._shown: dict[tuple[int, int], float] = {}  # (sender, entry) -> first time the sender showed it
        self._active: set[int] = set()  # sender << 40 | slot (see _activity_code)
        self._origin: float | None = None  # activity slots count from here
        self._sender_links: set[int] = set()
        # Senders by index, as the codes below hold them: they pack a sender into a few bits, and an XBee
        # module's sender is its 64-bit address. Index i stands for _senders[i]; NO_SENDER stays itself.
        self._senders: list[int] = []
        self._sender_index: dict[int, int] = {}
        self._pending: list[tuple[float, int, int, Message]] = []
        self._timelines: dict[int, list[tuple[I64, I64]]] = defaultdict(list)  # link -> (slots, counts) parts
        self._timeline_start: float | None = None

    def link(self, name: str) -> int:
        """The index of link `name` in `Batch.link` (registered on first use)."""
        index = self._link_index.get(name)
        if index is None:
            index = self._link_index[name] = len(self.links)
            self.links.append(name)
        return index

    def add_messages(self, rows: Iterable[tuple[float, int, int, Message]]) -> None:
        """(t, link index, sender or NO_SENDER, message) one by one; aggregated in batches."""
        pending = self._pending
        for row in rows:
            pending.append(row)
            if len(pending) >= _BATCH:
                self._flush()
                pending = self._pending  # _flush starts a new list: appending to the old one would lose rows

    def _flush(self) -> None:
        rows, self._pending = self._pending, []
        if not rows:
            return
        t, link, sender, msgs = zip(*rows, strict=True)
        head, value, ts, robot = (np.array(c, dtype=np.int64) for c in zip(*msgs, strict=True))
        self.add(Batch(np.array(t, dtype=np.float64), np.array(link, dtype=np.int64),
                       np.array(sender, dtype=np.int64), head >> 15, head & KEY_MAX, value, ts, robot))

    def _indexed(self, sender: I64) -> I64:
        """The senders as indices into `_senders` (NO_SENDER stays), registering new ones."""
        values, inverse = np.unique(sender, return_inverse=True)
        index, senders = self._sender_index, self._senders
        for value in values.tolist():
            if value != NO_SENDER and value not in index:
                index[value] = len(senders)
                senders.append(value)
        return np.array([index.get(v, NO_SENDER) for v in values.tolist()], dtype=np.int64)[inverse]

    def add(self, batch: Batch) -> None:
        if not len(batch):
            return
        sender = indexed = self._indexed(batch.sender)
        t, link, op = batch.t, batch.link, batch.op
        self._messages += len(batch)
        low, high = float(t.min()), float(t.max())
        self._start = low if self._start is None else min(self._start, low)
        self._end = high if self._end is None else max(self._end, high)

        traffic_code = (link << 18) | ((sender + 1) << 1) | op
        codes, counts = np.unique(traffic_code, return_counts=True)
        for code, count in zip(codes.tolist(), counts.tolist(), strict=True):
            self._traffic[(code >> 18, ((code >> 1) & 0x1FFFF) - 1, code & 1)] += count

        entry = (batch.key << 32) | (batch.timestamp << 16) | batch.robot
        is_put = op == 0
        self._puts += int(is_put.sum())
        self._put_entries.update(np.unique((entry[is_put] << 16) | batch.value[is_put]).tolist())

        has_entry = batch.timestamp != TS_NONE
        entry, t, link, sender = entry[has_entry], t[has_entry], link[has_entry], sender[has_entry]
        value = batch.value[has_entry]
        writes = self._writes
        for code, row, _, _ in zip(*_first_last(entry, t), strict=True):
            seen = writes.get(code)
            if seen is None or t[row] < seen[0]:
                writes[code] = (float(t[row]), int(link[row]), int(value[row]))

        heard = self._heard
        for code, first, last, copies in zip(*_first_last((link << _ENTRY_BITS) | entry, t), strict=True):
            slot = (code >> _ENTRY_BITS, code & _ENTRY_MASK)
            span = heard.get(slot)
            if span is None:
                heard[slot] = [float(t[first]), float(t[last]), copies]
            else:
                span[0], span[1], span[2] = min(span[0], float(t[first])), max(span[1], float(t[last])), \
                    span[2] + copies

        known = sender >= 0
        shown = self._shown
        t_known = t[known]
        for code, row, _, _ in zip(*_first_last((sender[known] << _ENTRY_BITS) | entry[known], t_known),
                                   strict=True):
            slot = (code >> _ENTRY_BITS, code & _ENTRY_MASK)
            when = float(t_known[row])
            if when < shown.get(slot, math.inf):
                shown[slot] = when

        self._count_over_time(batch.t, batch.link)
        named = batch.sender >= 0
        self._sender_links.update(np.unique(batch.link[named]).tolist())
        self._active.update(np.unique(self._activity_code(indexed[named], batch.t[named])).tolist())

    def _count_over_time(self, t: F64, link: I64) -> None:
        """Add the batch to each link's messages per slot (slots count from the first message read)."""
        if self._timeline_start is None:
            self._timeline_start = float(t.min())
        slot = np.floor((t - self._timeline_start) / TIMELINE_STEP + _ON_EDGE).astype(np.int64)
        for index in np.unique(link).tolist():
            parts = self._timelines[index]
            parts.append(np.unique(slot[link == index], return_counts=True))
            if len(parts) >= _TIMELINE_PARTS:
                parts[:] = [_summed(parts)]

    def _activity_code(self, sender: I64, t: F64) -> I64:
        """sender << 40 | the window/8-wide time slot it was heard in (slots count from the first message)."""
        if self._origin is None:
            self._origin = float(t.min()) if len(t) else 0.0
        slot = np.floor((t - self._origin) / self._slot).astype(np.int64) + _SLOT_ZERO
        return (sender << 40) | slot

    # -- the figures -----------------------------------------------------------
    def _newer(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> bool:
        """Entry a (timestamp, robot, value) is newer than b."""
        if a[0] != b[0]:
            return is_newer(a[0], b[0])
        if self.conflict == "value":
            return (a[2], a[1]) > (b[2], b[1])
        return a[1] > b[1]

    def report(self) -> Report:
        self._flush()
        by_key: dict[int, list[int]] = defaultdict(list)
        for code in self._writes:
            by_key[code >> 32].append(code)
        rank: dict[int, int] = {}
        for codes in by_key.values():
            def compare(a: int, b: int) -> int:
                ea, eb = self._entry(a), self._entry(b)
                return 1 if self._newer(ea, eb) else -1 if self._newer(eb, ea) else 0
            for position, code in enumerate(sorted(codes, key=functools.cmp_to_key(compare))):
                rank[code] = position
        # Per (sender, key): when the sender's newest shown entry rose, and to which rank.
        shows: dict[tuple[int, int], list[tuple[float, int]]] = defaultdict(list)
        for (sender, code), when in self._shown.items():
            shows[(sender, code >> 32)].append((when, rank[code]))
        frontier: dict[tuple[int, int], tuple[F64, I64]] = {}
        for slot, events in shows.items():
            times: list[float] = []
            ranks: list[int] = []
            for when, r in sorted(events):
                if not ranks or r > ranks[-1]:
                    times.append(when)
                    ranks.append(r)
            frontier[slot] = (np.array(times, dtype=np.float64), np.array(ranks, dtype=np.int64))
        # Per sender: the sorted slots it was heard in.
        active = np.array(sorted(self._active), dtype=np.int64)
        owner = active >> 40
        activity: dict[int, I64] = {}
        for group in np.split(active, np.flatnonzero(owner[1:] != owner[:-1]) + 1) if len(active) else []:
            activity[int(group[0] >> 40)] = (group & ((1 << 40) - 1)) - _SLOT_ZERO
        heard: dict[int, dict[str, LinkHeard]] = defaultdict(dict)
        for (link, code), span in sorted(self._heard.items()):
            heard[code][self.links[link]] = LinkHeard(span[0], span[1], int(span[2]))

        reports: dict[int, WriteReport] = {}
        for key, codes in by_key.items():
            reports.update(self._key_reports(key, codes, rank, frontier, activity, heard))
        writes = [reports[code] for code in sorted(self._writes, key=lambda c: (self._writes[c][0], c))]
        links: dict[str, Traffic] = {name: Traffic() for name in self.links}
        senders: dict[int, Traffic] = defaultdict(Traffic)
        for (link, sender, op), count in sorted(self._traffic.items()):
            for traffic in (links[self.links[link]], senders[sender] if sender >= 0 else None):
                if traffic is not None:
                    traffic.messages += count
                    if op:
                        traffic.gets += count
                    else:
                        traffic.puts += count
        same_slot: dict[int, int] = defaultdict(int)
        for code in self._writes:
            same_slot[code >> 16] += 1
        return Report(
            start=self._start, end=self._end, messages=self._messages, window=self.window,
            conflict=self.conflict, writes=writes, links={name: t for name, t in links.items() if t.messages},
            senders=dict(sorted((self._senders[index], traffic) for index, traffic in senders.items())),
            first_copies=len(self._put_entries), rebroadcasts=self._puts - len(self._put_entries),
            conflicts=sum(n for n in same_slot.values() if n > 1),
            links_without_sender=[name for i, name in enumerate(self.links)
                                  if i not in self._sender_links and links[name].messages],
            timelines=self._timeline_report())

    def _timeline_report(self) -> dict[str, Timeline]:
        start = self._timeline_start or 0.0
        return {self.links[index]: Timeline(start, *_summed(parts)) for index, parts in sorted(self._timelines.items())}

    def _entry(self, code: int) -> tuple[int, int, int]:
        """(timestamp, robot, value) of a write code (the value it first appeared with)."""
        return (code >> 16) & 0xFFFF, code & 0xFFFF, self._writes[code][2]

    def _key_reports(self, key: int, codes: list[int], rank: dict[int, int],
                     frontier: dict[tuple[int, int], tuple[F64, I64]], activity: dict[int, I64],
                     heard: dict[int, dict[str, LinkHeard]]) -> Iterator[tuple[int, WriteReport]]:
        """One key's writes, a block of writes x every sender at a time."""
        senders = sorted(activity)
        origin = self._origin or 0.0
        for start in range(0, len(codes), _BLOCK):
            block = codes[start:start + _BLOCK]
            t = np.array([self._writes[code][0] for code in block])
            ranks = np.array([rank[code] for code in block])
            low = np.floor((t - self.window - origin) / self._slot)
            high = np.floor((t + self.window - origin) / self._slot)
            is_active = np.zeros((len(block), len(senders)), dtype=bool)
            after = np.full((len(block), len(senders)), np.nan)  # NaN: never showed it or newer
            for column, sender in enumerate(senders):
                slots = activity[sender]
                at = np.minimum(np.searchsorted(slots, low), len(slots) - 1)
                is_active[:, column] = (slots[at] >= low) & (slots[at] <= high)
                times, reached_ranks = frontier.get((sender, key), _NEVER)
                if len(times):
                    reached = np.searchsorted(reached_ranks, ranks)
                    when = times[np.minimum(reached, len(times) - 1)]
                    after[:, column] = np.where(reached < len(times), np.maximum(0.0, when - t), np.nan)
            behind_mask = is_active & np.isnan(after)
            for row, code in enumerate(block):
                caught = np.sort(after[row][is_active[row] & ~behind_mask[row]]).tolist()
                behind = sorted(self._senders[senders[column]] for column in np.flatnonzero(behind_mask[row]).tolist())
                first, link, value = self._writes[code]
                yield code, WriteReport(key, value, (code >> 16) & 0xFFFF, code & 0xFFFF, first, self.links[link],
                                        len(caught) + len(behind), tuple(caught), tuple(behind),
                                        heard.get(code, {}), rank[code])
