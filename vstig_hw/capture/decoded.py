"""Captured units to Messages, and Messages to text, JSON lines or CSV.

Each (link, framing, direction) gets its own framing instance, so fragments
(epuck4) reassemble per radio exactly as they did live.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from ..counters import Counters
from ..values import ValueType, from_raw
from ..wire import Message
from .records import CAN_FRAMING, MESSAGE_FRAMING, Record

__all__ = ["CSV_HEADER", "Decoded", "Decoder", "as_csv", "as_json", "as_text"]

CSV_HEADER = "t,link,can_id,op,key,value,timestamp,robot\n"


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
    from ..framing import make_serial_framing
    from ..framing.can import can_framing
    from ..framing.zenoh import ZenohFraming, ZenohKeySpace

    def make(record: Record) -> Any:
        if record.framing == CAN_FRAMING:
            return can_framing(id_base, bool(record.unit.is_extended_id) if extended is None else extended)
        if record.framing == ZenohFraming.name:  # the key space the link subscribed to, read off its first key
            return ZenohFraming(ZenohKeySpace.of_key(record.unit.key), sender=0)
        if record.framing == MESSAGE_FRAMING:
            from .rosbag import CarriedMessages

            return CarriedMessages()
        from ..dialects.framing import DIALECT_FRAMINGS, make_dialect_framing

        if record.framing in DIALECT_FRAMINGS:
            if deployment is None:
                raise ValueError(f"{record.framing} records are in a robot dialect: give the deployment file that "
                                 "maps its keys (--deployment FILE.toml)")
            from ..dialects.mapping import load_deployment

            return make_dialect_framing(record.framing, load_deployment(deployment))
        return make_serial_framing(record.framing)

    return make


class Decoder:
    def __init__(self, framings: FramingFactory | None = None) -> None:
        self._make = framings or default_framings()
        self._framings: dict[tuple[str, str, str], Any] = {}

    def drops(self) -> Counters:
        total = Counters()
        for framing in self._framings.values():
            total.update(framing.drops)
        return total

    def _framing(self, record: Record) -> Any:
        slot = (record.link, record.framing, record.direction)
        framing = self._framings.get(slot)
        if framing is None:
            framing = self._framings[slot] = self._make(record)
        return framing

    def sender_of(self, record: Record) -> int | None:
        """The node that sent a record, where its medium names one (a CAN frame's ID); else None."""
        sender_of = getattr(self._framing(record), "sender_of", None)
        return None if sender_of is None else sender_of(record.unit)

    def decode(self, record: Record) -> list[Decoded]:
        framing = self._framing(record)
        is_can = record.framing == CAN_FRAMING
        can_id = int(record.unit.arbitration_id) if is_can else None
        messages = framing.feed(record.unit)
        sender_of = getattr(framing, "sender_of", None) if messages else None
        sender = None if sender_of is None else sender_of(record.unit)
        return [Decoded(record.t, record.link, can_id, msg, sender) for msg in messages]

    def decode_all(self, records: Iterable[Record]) -> Iterator[Decoded]:
        for record in records:
            yield from self.decode(record)


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
    return (f"{stamp or f'({d.t:.6f})'} {d.link}{can_id} {m.op.name} key={m.key} value={from_raw(m.value, value_type)} "
            f"ts={m.timestamp} robot={m.robot}")


def as_csv(d: Decoded, value_type: ValueType = "uint16") -> str:
    m = d.message
    can_id = "" if d.can_id is None else str(d.can_id)
    return (f"{d.t:.6f},{d.link},{can_id},{m.op.name},{m.key},{from_raw(m.value, value_type)},"
            f"{m.timestamp},{m.robot}")
