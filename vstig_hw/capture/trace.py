"""Captures read once into a per-key index of what each sender showed when (`vstig why`).

Every PUT or GET a robot sends shows the entry it holds for the key, so the messages a capture holds, merged
by time on one clock (as analyze merges them), say for each key what each sender showed when; a recording
gateway's own sends (direction `tx`) say what it sent on each link, and its decision notes
(capture.decision_notes) what it decided that the wire does not show. `read_trace` reads the captures once and
files every message under its key; every question afterwards (`capture.why`) looks at one key's list only.

A sender is who a message came from: its id where the medium names one (a CAN ID, a zenoh key), else the link
it was heard on (a serial port reaches one robot), as `sender_label` writes it.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

from ..timestamps import TS_NONE, is_newer
from .decision_notes import Decision, decisions_in
from .decoded import Decoder, default_framings
from .records import CaptureError, Record, line_capture_at, read_capture, sniff

__all__ = ["Shown", "Trace", "newer_entry", "read_trace", "sender_label"]


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


@dataclass
class Trace:
    """Every message of the captures filed by key, in time order; the gateways' decision notes; when each
    sender was heard last."""

    start: float = 0.0  # the first record's time (every `t` here counts from it)
    end: float = 0.0
    keys: dict[int, list[Shown]] = field(default_factory=dict)
    decisions: list[Decision] = field(default_factory=list)
    heard: dict[str, list[float]] = field(default_factory=dict)  # sender -> times heard (any key), in order
    links_of: dict[str, set[str]] = field(default_factory=dict)  # sender -> links it was heard on
    messages: int = 0

    def of(self, key: int) -> list[Shown]:
        return self.keys.get(key, [])


def read_trace(paths: Sequence[str], *, shifts: Sequence[float] | None = None, skip_bad: bool = False,
               bad: list[CaptureError] | None = None, deployment: str | None = None) -> Trace:
    """Read `paths` once, merged by time (`shifts`: seconds off each file's times, clock_notes.shifts)."""
    formats = [sniff(path) for path in paths]
    readers: list[Iterator[Record]] = [read_capture(path, skip_bad, bad, fmt=fmt)
                                       for path, fmt in zip(paths, formats, strict=True)]
    if shifts is not None:
        readers = [_shifted(reader, shift) if shift else reader for reader, shift in zip(readers, shifts, strict=True)]
    trace = Trace()
    _file(trace, heapq.merge(*readers, key=lambda r: r.t), Decoder(default_framings(deployment=deployment)))
    notes = [_notes(path, shift) for path, shift in zip(paths, shifts or [0.0] * len(paths), strict=True)
             if line_capture_at(path) is not None]
    trace.decisions = [dataclasses.replace(d, t=d.t - trace.start) for d in heapq.merge(*notes, key=lambda d: d.t)]
    return trace


def _shifted(records: Iterable[Record], seconds: float) -> Iterator[Record]:
    for record in records:
        yield dataclasses.replace(record, t=record.t - seconds)


def _notes(path: str, shift: float) -> list[Decision]:
    with open(path, encoding="utf-8", errors="replace") as file:
        return [dataclasses.replace(d, t=d.t - shift) if shift else d for d in decisions_in(file)]


def _file(trace: Trace, records: Iterable[Record], decoder: Decoder) -> None:
    keys, heard, links_of = trace.keys, trace.heard, trace.links_of
    start: float | None = None
    t = 0.0
    for record in records:
        decoded = decoder.decode(record)
        if not decoded:
            continue
        if start is None:
            start = record.t
        t = record.t - start
        sent = record.direction == "tx"
        sender = record.link if sent else sender_label(decoded[0].sender, record.link)
        if not sent:
            times = heard.get(sender)
            if times is None:
                times, links_of[sender] = heard.setdefault(sender, []), set()
            times.append(t)
            links_of[sender].add(record.link)
        for d in decoded:
            msg = d.message
            shown = Shown(t, record.link, sent, sender, not msg.op, msg.value, msg.timestamp, msg.robot)
            listed = keys.get(msg.key)
            if listed is None:
                listed = keys[msg.key] = []
            listed.append(shown)
        trace.messages += len(decoded)
    trace.start, trace.end = start or 0.0, t
