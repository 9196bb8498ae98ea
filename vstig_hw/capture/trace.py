"""Captures read once into a per-key index of what each sender showed when (`vstig why`).

Every PUT or GET a robot sends shows the entry it holds for the key, so the messages a capture holds, merged
by time on one clock (as analyze merges them), say for each key what each sender showed when; a recording
gateway's own sends (direction `tx`) say what it sent on each link, and its decision notes
(capture.decision_notes) what it decided that the wire does not show.

`read_trace` reads the captures once into columns (numpy arrays, one row per message), sorted by key once, so
a question about one key turns only that key's rows into `Shown`s (`Trace.of`). A single candump log is read
as analyze reads it, chunk by chunk through `fastlog` where its lines are uniform; everything else record by
record through the framings.

A sender is who a message came from: its id where the medium names one (a CAN ID, a zenoh key), else the link
it was heard on (a serial port reaches one robot), as `sender_label` writes it.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..timestamps import TS_NONE, is_newer
from .analyzefile import candump_parts
from .decision_notes import Decision, decisions_in
from .decoded import Decoder, default_framings
from .fastlog import Chunk, seconds
from .notes import capture_notes
from .records import STRICT, Damage, Record, read_capture, sniff

__all__ = ["Shown", "Trace", "newer_entry", "read_trace", "sender_label"]

Column = npt.NDArray[Any]  # one field of every message: float64 times, int64 the rest
_COLUMNS = ("t", "link", "sent", "sender", "put", "key", "value", "ts", "robot")


def sender_label(sender: int | None, link: str) -> str:
    """Who sent a message: its id where the medium names one, else the link (one robot on a serial port)."""
    return link if sender is None else str(sender)


def newer_entry(a: tuple[int, int], b: tuple[int, int]) -> bool:
    """Whether entry a (timestamp, robot) is newer than b, as the engine decides by default: the newer
    timestamp, and on the same one the higher robot id."""
    if a[0] != b[0]:
        return is_newer(a[0], b[0])
    return a[1] > b[1]


@dataclass(frozen=True, slots=True)
class Shown:
    """One message of one key on the wire: who showed which entry, when, where."""

    t: float  # seconds since the first record of the captures
    link: str
    sent: bool  # the recording gateway sent it (a `tx` record); else it heard it
    sender: str  # `sender_label`; for a sent message, the link it went out on
    put: bool
    value: int
    ts: int
    robot: int

    @property
    def entry(self) -> tuple[int, int]:
        return self.ts, self.robot

    @property
    def holds(self) -> bool:
        """Whether it shows an entry (a GET with timestamp 0 says its sender holds none)."""
        return self.ts != TS_NONE


class _Columns:
    """Rows appended as they are read (lists, or numpy blocks from a bulk chunk), names interned."""

    def __init__(self) -> None:
        self.rows: dict[str, list[float | int]] = {name: [] for name in _COLUMNS}
        self.blocks: list[dict[str, Column]] = []
        self.links: dict[str, int] = {}
        self.senders: dict[str, int] = {}

    def link(self, name: str) -> int:
        return self.links.setdefault(name, len(self.links))

    def sender(self, name: str) -> int:
        return self.senders.setdefault(name, len(self.senders))

    def flush(self) -> None:
        """The rows so far as one block (before a bulk block, so that rows stay in time order)."""
        if self.rows["t"]:
            self.blocks.append({name: np.asarray(values, dtype=np.float64 if name == "t" else np.int64)
                                for name, values in self.rows.items()})
            self.rows = {name: [] for name in _COLUMNS}


@dataclass
class Trace:
    """Every message of the captures as columns sorted by key (time order within a key); the gateways'
    decision notes; names of links and senders."""

    start: float = 0.0  # the first record's time (every `t` here counts from it)
    end: float = 0.0
    messages: int = 0
    links: list[str] = field(default_factory=list)
    senders: list[str] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)
    columns: dict[str, Column] = field(default_factory=dict)  # by time
    _by_key: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))  # rows sorted by key
    _keys: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))  # key of each sorted row
    _shown: dict[int, list[Shown]] = field(default_factory=dict)
    _links_of: dict[str, set[str]] | None = None

    def index(self) -> None:
        """Sort the rows by key once (stable: time order stays within a key)."""
        keys = self.columns["key"].astype(np.int64)
        self._by_key = np.argsort(keys, kind="stable")
        self._keys = keys[self._by_key]

    @property
    def keys(self) -> list[int]:
        return [int(k) for k in np.unique(self._keys)]

    def count(self, key: int) -> int:
        return int(np.searchsorted(self._keys, key, "right") - np.searchsorted(self._keys, key, "left"))

    def of(self, key: int) -> list[Shown]:
        """The key's messages in time order (made once per key)."""
        found = self._shown.get(key)
        if found is None:
            rows = self._by_key[np.searchsorted(self._keys, key, "left"):np.searchsorted(self._keys, key, "right")]
            c = self.columns
            links, senders = self.links, self.senders
            found = self._shown[key] = [
                Shown(t, links[link], bool(sent), senders[sender], bool(put), value, ts, robot)
                for t, link, sent, sender, put, value, ts, robot in zip(
                    c["t"][rows].tolist(), c["link"][rows].tolist(), c["sent"][rows].tolist(),
                    c["sender"][rows].tolist(), c["put"][rows].tolist(), c["value"][rows].tolist(),
                    c["ts"][rows].tolist(), c["robot"][rows].tolist(), strict=True)]
        return found

    def last_heard(self, at: float) -> dict[str, float]:
        """When each sender was last heard (any key) at or before `at`."""
        c = self.columns
        heard = (c["t"] <= at) & (c["sent"] == 0)
        ids, times = c["sender"][heard][::-1], c["t"][heard][::-1]  # newest first: unique's first is the last
        found, first = np.unique(ids, return_index=True)
        return {self.senders[i]: t for i, t in zip(found.tolist(), times[first].tolist(), strict=True)}

    def links_of(self, sender: str) -> set[str]:
        """The links `sender` was heard on (all senders' found once)."""
        if self._links_of is None:
            c = self.columns
            heard = c["sent"] == 0
            pairs = np.unique(c["sender"][heard] * len(self.links) + c["link"][heard]).tolist()
            self._links_of = {}
            for pair in pairs:
                self._links_of.setdefault(self.senders[pair // len(self.links)], set()).add(
                    self.links[pair % len(self.links)])
        return self._links_of.get(sender, set())


def read_trace(paths: Sequence[str], *, shifts: Sequence[float] | None = None, damage: Damage = STRICT,
               deployment: str | None = None) -> Trace:
    """Read `paths` once, merged by time (`shifts`: seconds off each file's times, clock_notes.shifts)."""
    formats = [sniff(path) for path in paths]
    columns = _Columns()
    decoder = Decoder(default_framings(deployment=deployment))
    if formats == [".log"] and not shifts:
        _candump_chunks(paths[0], columns, decoder, damage)
    else:
        readers: list[Iterator[Record]] = [read_capture(path, damage, fmt=fmt)
                                           for path, fmt in zip(paths, formats, strict=True)]
        if shifts is not None:
            readers = [_shifted(reader, shift) if shift else reader
                       for reader, shift in zip(readers, shifts, strict=True)]
        _file(columns, heapq.merge(*readers, key=lambda r: r.t), decoder)
    trace = _finished(columns)
    notes = [_notes(path, shift) for path, shift in zip(paths, shifts or [0.0] * len(paths), strict=True)]
    trace.decisions = [dataclasses.replace(d, t=d.t - trace.start) for d in heapq.merge(*notes, key=lambda d: d.t)]
    return trace


def _finished(columns: _Columns) -> Trace:
    columns.flush()
    blocks = columns.blocks
    joined = {name: np.concatenate([b[name] for b in blocks]) if blocks else np.zeros(0) for name in _COLUMNS}
    trace = Trace(links=list(columns.links), senders=list(columns.senders), columns=joined,
                  messages=len(joined["t"]))
    if trace.messages:
        trace.start = float(joined["t"][0])
        joined["t"] = joined["t"] - trace.start
        trace.end = float(joined["t"][-1])
    trace.index()
    return trace


def _shifted(records: Iterable[Record], seconds: float) -> Iterator[Record]:
    for record in records:
        yield dataclasses.replace(record, t=record.t - seconds)


def _notes(path: str, shift: float) -> list[Decision]:
    return [dataclasses.replace(d, t=d.t - shift) if shift else d for d in decisions_in(capture_notes(path))]


def _file(columns: _Columns, records: Iterable[Record], decoder: Decoder) -> None:
    rows = columns.rows
    t_, link_, sent_, sender_, put_, key_, value_, ts_, robot_ = (rows[name] for name in _COLUMNS)
    for record in records:
        decoded = decoder.decode(record)
        if not decoded:
            continue
        sent = record.direction == "tx"
        link = columns.link(record.link)
        sender = columns.sender(record.link if sent else sender_label(decoded[0].sender, record.link))
        for d in decoded:
            head, value, ts, robot = d.message  # the wire words: the op in the key's top bit
            t_.append(record.t)
            link_.append(link)
            sent_.append(sent)
            sender_.append(sender)
            put_.append(not head >> 15)
            key_.append(head & 0x7FFF)
            value_.append(value)
            ts_.append(ts)
            robot_.append(robot)


def _candump_chunks(path: str, columns: _Columns, decoder: Decoder, damage: Damage) -> None:
    """A candump log as analyze reads it: uniform chunks in bulk, the others line by line."""
    for _size, part, max_sender in candump_parts(path, None, damage, {}):
        if not isinstance(part, Chunk):
            _file(columns, part, decoder)
            continue
        if not len(part.op):
            continue
        columns.flush()
        link = columns.link(part.link.decode())
        ids = part.can_id & max_sender
        names = np.zeros(int(ids.max()) + 1, np.int64)
        for sender in np.unique(ids).tolist():
            names[sender] = columns.sender(str(sender))
        count = len(part.op)
        columns.blocks.append({"t": seconds(part.stamp), "link": np.full(count, link, np.int64),
                               "sent": np.zeros(count, np.int64), "sender": names[ids], "put": 1 - part.op,
                               "key": part.key, "value": part.value, "ts": part.timestamp, "robot": part.robot})
