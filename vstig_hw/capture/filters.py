"""One filter for every command that reads or writes captures: record, decode, replay, analyze.

A `Filter` keeps a message when every criterion given holds: its key, the robot
of its entry, the node that sent it (where the medium names one: a CAN frame's
ID), its op, its link, and its time in seconds after the first record
(`since <= t < until`). `accepts` is the definition; `mask` is the same test
over numpy columns, for analyze's batches (tests hold the two equal).

Captures hold link units, not messages. `RecordFilter` keeps a unit whose
messages pass: a CAN frame when any of its messages passes (a classic frame holds
one), while a serial chunk, whose bytes need not align with frames, is decoded and
its passing messages re-encoded in the same framing.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from ..framing.base import Framing
from ..framing.zenoh import ZenohFraming, ZenohSample
from ..wire import KEY_MAX, Message, Op, encode
from .decoded import Decoded, Decoder
from .records import CAN_FRAMING, MESSAGE_FRAMING, Record

if TYPE_CHECKING:  # numpy comes with the analyze extra; record, replay and decode filter without it
    import numpy as np
    import numpy.typing as npt

__all__ = ["Filter", "RecordFilter", "filter_records"]

Set = frozenset[int] | None


@dataclass(frozen=True)
class Filter:
    keys: Set = None
    robots: Set = None  # the robot field of the entry (who wrote it)
    senders: Set = None  # the node that sent the message: a CAN frame's sender field
    ops: frozenset[Op] | None = None
    links: frozenset[str] | None = None
    since: float | None = None  # seconds after the first record
    until: float | None = None

    @property
    def by_message(self) -> bool:
        """Whether a unit must be decoded to decide (anything beyond link and time)."""
        return any(c is not None for c in (self.keys, self.robots, self.senders, self.ops))

    def __bool__(self) -> bool:
        return self.by_message or any(c is not None for c in (self.links, self.since, self.until))

    def accepts_unit(self, t: float, link: str) -> bool:
        """The link and time criteria alone; `t` in seconds after the first record."""
        return ((self.links is None or link in self.links) and (self.since is None or t >= self.since)
                and (self.until is None or t < self.until))

    def accepts(self, t: float, link: str, sender: int | None, message: Message) -> bool:
        head, _, _, robot = message
        return (self.accepts_unit(t, link)
                and (self.keys is None or head & KEY_MAX in self.keys)
                and (self.robots is None or robot in self.robots)
                and (self.senders is None or sender in self.senders)
                and (self.ops is None or Op(head >> 15) in self.ops))

    def mask(self, t: npt.NDArray[np.float64], link: npt.NDArray[np.int64], link_names: Sequence[str],
             sender: npt.NDArray[np.int64], op: npt.NDArray[np.int64], key: npt.NDArray[np.int64],
             robot: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
        """`accepts` over columns (t after the first record; link as indices into `link_names`; sender -1: none)."""
        import numpy as np

        keep = np.ones(len(t), dtype=bool)
        if self.links is not None:
            wanted = [i for i, name in enumerate(link_names) if name in self.links]
            keep &= np.isin(link, wanted)
        if self.since is not None:
            keep &= t >= self.since
        if self.until is not None:
            keep &= t < self.until
        for column, wanted_values in ((key, self.keys), (robot, self.robots), (sender, self.senders)):
            if wanted_values is not None:
                keep &= np.isin(column, list(wanted_values))
        if self.ops is not None:
            keep &= np.isin(op, [int(o) for o in self.ops])
        return keep


class RecordFilter:
    """A `Filter` applied along one capture: times count from its first record (`t0`)."""

    def __init__(self, keep: Filter, decoder: Decoder | None = None) -> None:
        self.keep = keep
        self.decoder = decoder or Decoder()
        self.t0: float | None = None
        self.filtered_out = 0  # messages `messages` decoded but did not pass
        self._encoders: dict[str, Framing[bytes]] = {}

    def since_start(self, t: float) -> float:
        if self.t0 is None:
            self.t0 = t
        return t - self.t0

    def messages(self, record: Record) -> tuple[int | None, list[Decoded]]:
        """The record's sender (None if its medium names none) and its messages that pass."""
        t = self.since_start(record.t)
        decoded = self.decoder.decode(record)
        sender = self.decoder.sender_of(record) if decoded else None
        if self.keep:
            passed = [d for d in decoded if self.keep.accepts(t, record.link, sender, d.message)]
            self.filtered_out += len(decoded) - len(passed)
            decoded = passed
        return sender, decoded

    def units(self, record: Record) -> list[Record]:
        """The record if its unit passes, none if not; a serial chunk decided by message comes back re-encoded."""
        if not self.keep.accepts_unit(self.since_start(record.t), record.link):
            return []
        if not self.keep.by_message:
            return [record]
        _, passed = self.messages(record)
        if record.framing in (CAN_FRAMING, MESSAGE_FRAMING):  # one message per unit (classic CAN, MCAP)
            return [record] if passed else []
        if record.framing == ZenohFraming.name:  # a sample keeps its key (its sender) and carries what passed
            payload = b"".join(encode(d.message) for d in passed)
            sample = ZenohSample(record.unit.key, payload)
            return [Record(record.t, record.link, record.framing, sample, record.direction)] if payload else []
        encoder = self._encoder(record.framing)
        chunk = b"".join(unit for d in passed for unit in encoder.encode(d.message))
        return [Record(record.t, record.link, record.framing, chunk, record.direction)] if chunk else []

    def _encoder(self, framing: str) -> Framing[bytes]:
        from ..framing import make_serial_framing

        encoder = self._encoders.get(framing)
        if encoder is None:
            encoder = self._encoders[framing] = make_serial_framing(framing)
        return encoder


def filter_records(records: Iterable[Record], keep: Filter, decoder: Decoder | None = None) -> Iterator[Record]:
    """The records of a capture that pass `keep` (all of them, unchanged, for an empty filter)."""
    if not keep:
        yield from records
        return
    passing = RecordFilter(keep, decoder)
    for record in records:
        yield from passing.units(record)
