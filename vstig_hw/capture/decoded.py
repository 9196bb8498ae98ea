"""Decoding: captured records to Messages (those a `Filter` keeps), and Messages to text, JSON lines or CSV.

Each (link, framing, direction) gets its own framing instance, so fragments
(epuck4) reassemble per radio exactly as they did live. A framing's module is
imported when the first record of its kind comes: a candump log loads the CAN
framing alone, no dialect.

`decode_file` reads candump logs in chunks of whole lines; in a log big enough
to pay for numpy (installed with the analyze extra), a uniform chunk goes
through the vectorised `fastlog` path (JSON lines only), any other chunk line by
line. Every other capture type goes record by record through the framings.

`RecordFilter` keeps a unit whose messages pass: a CAN frame when any of its
messages passes (a classic frame holds one), while a serial chunk, whose bytes
need not align with frames, is decoded and its passing messages re-encoded in
the same framing; an XBee frame is rebuilt with its own header (its sender) and
the messages that passed.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import IO, TYPE_CHECKING, Any

from ..counters import Counters
from ..extras import missing
from ..values import ValueType, from_raw
from ..wire import Message
from ..wording import shown_sender
from .records import CAN_FRAMING, MESSAGE_FRAMING, STRICT, Damage, Record, file_position, read_capture, sniff

if TYPE_CHECKING:
    from ..framing.base import Framing
    from .fastlog import Classify
    from .filters import Filter
    from .time_columns import TimeColumn

__all__ = ["CSV_HEADER", "FORMATS", "CarriedMessages", "Decoded", "Decoder", "RecordFilter", "as_csv", "as_json",
           "as_text", "decode_file", "default_framings", "filter_records"]

CSV_HEADER = "t,link,can_id,op,key,value,timestamp,robot,sender\n"


@dataclass(frozen=True, slots=True)
class Decoded:
    t: float
    link: str
    can_id: int | None
    message: Message
    sender: int | None = None  # the node that sent it, where the medium names one (a CAN ID's sender field)


FramingFactory = Callable[[Record], Any]


def default_framings(id_base: int | None = None, extended: bool | None = False,
                     deployment: str | None = None) -> FramingFactory:
    """Framings by the name a record carries: `extended=None` takes each CAN link's ID width from its first
    frame; robot dialects (Buzz, BittyBuzz) need their `deployment` file."""

    def make(record: Record) -> Any:
        if record.framing == CAN_FRAMING:
            from ..framing.can import can_framing

            return can_framing(id_base, bool(record.unit.is_extended_id) if extended is None else extended)
        if record.framing == MESSAGE_FRAMING:
            return CarriedMessages()
        if record.framing == "zenoh":  # the key space the link subscribed to, read off its first key
            from ..framing.zenoh import ZenohFraming, ZenohKeySpace

            return ZenohFraming(ZenohKeySpace.of_key(record.unit.key), sender=0)
        from ..dialects.framing import DIALECT_FRAMINGS, make_dialect_framing

        if record.framing in DIALECT_FRAMINGS:
            if deployment is None:
                raise ValueError(f"{record.framing} records are in a robot dialect: give the deployment file that "
                                 "maps its keys (--deployment FILE.toml)")
            from ..dialects.mapping import load_deployment

            return make_dialect_framing(record.framing, load_deployment(deployment))
        from ..framing import make_serial_framing

        return make_serial_framing(record.framing)

    return make


class CarriedMessages:
    """The framing of records that carry `(Message, sender)` already (read from MCAP)."""

    name = MESSAGE_FRAMING

    def __init__(self) -> None:
        self.drops = Counters()

    def feed(self, unit: tuple[Message, int | None]) -> list[Message]:
        return [unit[0]]

    def encode(self, msg: Message) -> list[tuple[Message, int | None]]:
        return [(msg, None)]

    def sender_of(self, unit: tuple[Message, int | None]) -> int | None:
        return unit[1]

    def tick(self) -> None:
        """Nothing to expire."""


class Decoder:
    def __init__(self, framings: FramingFactory | None = None) -> None:
        self._make = framings or default_framings()
        self._framings: dict[tuple[str, str, str], Any] = {}

    def drops(self) -> Counters:
        total = Counters()
        for framing in self._framings.values():
            total.update(framing.drops)
        return total

    def framing_of(self, record: Record) -> Any:
        """The framing instance that decodes this record's link, framing and direction."""
        return self._framing(record)

    def _framing(self, record: Record) -> Any:
        slot = (record.link, record.framing, record.direction)
        framing = self._framings.get(slot)
        if framing is None:
            framing = self._framings[slot] = self._make(record)
        return framing

    def sender_of(self, record: Record) -> int | None:
        """The node that sent a record, where its medium names one (a CAN frame's ID); else None."""
        sender: int | None = self._framing(record).sender_of(record.unit)
        return sender

    def decode(self, record: Record) -> list[Decoded]:
        framing = self._framing(record)
        is_can = record.framing == CAN_FRAMING
        can_id = int(record.unit.arbitration_id) if is_can else None
        messages = framing.feed(record.unit)
        sender = framing.sender_of(record.unit) if messages else None
        return [Decoded(record.t, record.link, can_id, msg, sender) for msg in messages]

    def decode_all(self, records: Iterable[Record]) -> Iterator[Decoded]:
        for record in records:
            yield from self.decode(record)


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
        framing = self.decoder.framing_of(record)
        if framing.narrows:  # a unit that names its sender (an XBee frame, a zenoh sample) keeps it, with what passed
            unit = framing.narrow(record.unit, [d.message for d in passed]) if passed else None
            return [Record(record.t, record.link, record.framing, unit, record.direction)] if unit else []
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


def as_json(d: Decoded, value_type: ValueType = "uint16") -> str:
    m = d.message
    row: dict[str, Any] = {"t": round(d.t, 6), "link": d.link}
    if d.can_id is not None:
        row["can_id"] = d.can_id
    row.update(op=m.op.name, key=m.key, value=from_raw(m.value, value_type), timestamp=m.timestamp, robot=m.robot,
               sender=d.sender)
    return json.dumps(row)


def as_text(d: Decoded, value_type: ValueType = "uint16", stamp: str | None = None) -> str:
    """One readable line; `stamp` replaces the time column (capture.time_columns)."""
    m = d.message
    can_id = f" id={d.can_id:03X}" if d.can_id is not None else ""
    sender = f" sender={shown_sender(d.sender)}" if d.sender is not None else ""
    return (f"{stamp or f'({d.t:.6f})'} {d.link}{can_id} {m.op.name} key={m.key} value={from_raw(m.value, value_type)} "
            f"ts={m.timestamp} robot={m.robot}{sender}")


def as_csv(d: Decoded, value_type: ValueType = "uint16") -> str:
    m = d.message
    can_id = "" if d.can_id is None else str(d.can_id)
    sender = "" if d.sender is None else str(d.sender)
    return (f"{d.t:.6f},{d.link},{can_id},{m.op.name},{m.key},{from_raw(m.value, value_type)},"
            f"{m.timestamp},{m.robot},{sender}")


FORMATS = {"text": as_text, "jsonl": as_json, "csv": as_csv}
_PROGRESS_EVERY = 4096  # records between progress reports on the record-by-record path
CHUNK = 1 << 22  # bytes per candump chunk: big enough to amortise numpy, small enough for a smooth progress bar
# The smallest candump log the numpy path is taken for: loading numpy and fastlog's tables costs about
# 0.1 s, what the line-by-line path spends on some 20,000 lines (measured: the two break even near 0.8 MB).
FAST_PATH_BYTES = 1 << 20


def decode_file(path: str, out: IO[str], fmt: str = "jsonl", *, value_type: ValueType = "uint16",
                damage: Damage = STRICT, id_base: int | None = None, extended: bool = False,
                progress: Callable[[int], None] | None = None, keep: Filter | None = None,
                csv_header: bool = True, file_column: bool = False, deployment: str | None = None,
                clock: TimeColumn | None = None) -> tuple[int, Counters]:
    """Write every message in `path` that `keep` passes to `out`; returns (messages, drops). Damage in the
    file goes to `damage` (raised, or counted and skipped).

    `progress` is told, now and then, how many bytes of the file were read so far (every format).
    CSV: `csv_header=False` leaves the header out (a later file of several); `file_column` adds a
    first column naming the file. Text: `clock` writes the time column (candump's -t styles).
    """
    formatter = _with_file(path) if fmt == "csv" and file_column else FORMATS[fmt]
    if fmt == "text" and clock is not None:
        formatter = _with_clock(clock)
    decoder = Decoder(default_framings(id_base, extended, deployment))
    if fmt == "csv" and csv_header:
        out.write(("file," if file_column else "") + CSV_HEADER)
    capture_format = sniff(path)
    if capture_format == ".log" and fmt == "jsonl" and value_type == "uint16" and not extended and not keep:
        count, drops = _candump_chunks(path, out, decoder, value_type, damage, id_base, progress)
        drops.update(decoder.drops())
        return count, drops
    count = 0
    reading: list[IO[Any]] = []
    messages = _passing(keep, decoder)
    for number, record in enumerate(read_capture(path, damage, reading.append, capture_format)):
        for decoded in messages(record):
            out.write(formatter(decoded, value_type) + "\n")
            count += 1
        if progress and number % _PROGRESS_EVERY == 0 and reading:
            progress(file_position(reading[0]) or 0)
    if progress:  # the end, also for a reader that does not show its file (MCAP)
        progress(os.path.getsize(path))
    return count, decoder.drops()


def _passing(keep: Filter | None, decoder: Decoder) -> Callable[[Record], list[Decoded]]:
    """A record's messages that `keep` passes (every one, with no filter: the filters module is not loaded)."""
    if not keep:
        return decoder.decode
    passing = RecordFilter(keep, decoder)
    return lambda record: passing.messages(record)[1]


def _with_clock(clock: TimeColumn) -> Callable[[Decoded, ValueType], str]:
    def line(decoded: Decoded, value_type: ValueType) -> str:
        return as_text(decoded, value_type, clock(decoded.t))

    return line


def _with_file(path: str) -> Callable[[Decoded, ValueType], str]:
    quoted = '"' + path.replace('"', '""') + '"'

    def row(decoded: Decoded, value_type: ValueType) -> str:
        return f"{quoted},{as_csv(decoded, value_type)}"

    return row


def _candump_chunks(path: str, out: IO[str], decoder: Decoder, value_type: ValueType, damage: Damage,
                    id_base: int | None, progress: Callable[[int], None] | None) -> tuple[int, Counters]:
    from ..framing.can import can_framing

    scheme = can_framing(id_base, False).scheme

    def classify(can_id: int) -> int | None:
        parsed = scheme.parse(can_id, False)
        return None if parsed is None else int(parsed[0])

    fast_drops: dict[str, int] = {}
    count = 0
    done = 0
    raw_out: Any = getattr(out, "buffer", None)
    chunk_to_jsonl = _fast_path(path)
    from . import candump

    for line_no, chunk in candump.chunks(path, CHUNK):
        lines = chunk.count(b"\n") + (0 if chunk.endswith(b"\n") else 1)
        dropped_before = sum(fast_drops.values())
        fast = chunk_to_jsonl(chunk, classify, fast_drops) if chunk_to_jsonl else None
        if fast is not None:
            count += lines - sum(fast_drops.values()) + dropped_before
            if raw_out is not None:
                out.flush()
                raw_out.write(fast)
            else:
                out.write(fast.decode())
        else:
            count += _slow(path, chunk, line_no, out, decoder, value_type, damage)
        done += len(chunk)
        if progress:
            progress(done)
    return count, Counters(fast_drops)


def _fast_path(path: str) -> Callable[[bytes, Classify, dict[str, int]], bytes | None] | None:
    """fastlog's chunk decoder for a log big enough to pay for loading numpy, if numpy is installed."""
    if os.path.getsize(path) < FAST_PATH_BYTES or missing(("numpy",)):
        return None
    from .fastlog import chunk_to_jsonl

    return chunk_to_jsonl


def _slow(path: str, chunk: bytes, first_line: int, out: IO[str], decoder: Decoder, value_type: ValueType,
          damage: Damage) -> int:
    count = 0
    from .candump import chunk_records

    for decoded in decoder.decode_all(chunk_records(path, chunk, first_line, damage)):
        out.write(as_json(decoded, value_type) + "\n")
        count += 1
    return count
