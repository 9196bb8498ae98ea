"""`cobs8`: one 8-byte wire message per serial frame (12 bytes on the wire), or one authenticated message (a
20-byte record: message, epoch, tag; 24 bytes on the wire, SPEC.md 10.5) told apart by its length.

C twin: vstig_hw/_cext/framing.c (Receiver, Encoder); held equal by tests/native (index: vstig_hw/_vstig.pyi).
The twin decodes records too (their messages, and the records where the link checks tags), and sends them
(`Encoder.send_tags`).

The default for UART radios that carry whole messages (Kilobot/marXbot style
bridges, generic serial radios).
"""

from __future__ import annotations

from collections.abc import Sequence

from ..auth import RECORD_SIZE, Tagged, decode_record, encode_record
from ..counters import Counters
from ..wire import MESSAGE_SIZE, Message, decode, encode
from .base import SerialFraming
from .cobsframe import DELIMITER, CobsFrameReader, encode_frame

__all__ = ["Cobs8Framing"]


class Cobs8Framing(SerialFraming):
    name = "cobs8"
    default_baud = 115200
    transmit_only = False
    preamble = DELIMITER  # sent before the first frame after the port opens (SPEC 6.0.3)
    carries_tags = True

    def __init__(self) -> None:
        self.drops = Counters()
        self._reader = CobsFrameReader(MESSAGE_SIZE, self.drops, tagged_size=RECORD_SIZE)

    def encode(self, msg: Message) -> list[bytes]:
        return [encode_frame(encode(msg))]

    def encode_tagged(self, records: Sequence[Tagged]) -> list[bytes]:
        """One authenticated frame per record."""
        return [encode_frame(encode_record(record)) for record in records]

    def feed(self, unit: bytes) -> list[Message]:
        return [decode(payload[:MESSAGE_SIZE]) for payload in self._reader.feed(unit)]

    def feed_tagged(self, unit: bytes) -> list[tuple[Message, Tagged | None]]:
        heard: list[tuple[Message, Tagged | None]] = []
        for payload in self._reader.feed(unit):
            if len(payload) == RECORD_SIZE:
                record = decode_record(payload)
                heard.append((record.message, record))
            else:
                heard.append((decode(payload), None))
        return heard

    def tick(self) -> None:
        """Nothing ages in a cobs8 stream."""

    def reset(self) -> None:
        self._reader.reset()
