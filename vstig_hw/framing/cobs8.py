"""`cobs8`: one 8-byte wire message per serial frame (12 bytes on the wire).

C twin: vstig_hw/_cext/framing.c (Receiver, Encoder); held equal by tests/native (index: vstig_hw/_vstig.pyi).

The default for UART radios that carry whole messages (Kilobot/marXbot style
bridges, generic serial radios).
"""

from __future__ import annotations

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

    def __init__(self) -> None:
        self.drops = Counters()
        self._reader = CobsFrameReader(MESSAGE_SIZE, self.drops)

    def encode(self, msg: Message) -> list[bytes]:
        return [encode_frame(encode(msg))]

    def feed(self, unit: bytes) -> list[Message]:
        return [decode(payload) for payload in self._reader.feed(unit)]

    def tick(self) -> None:
        """Nothing ages in a cobs8 stream."""

    def reset(self) -> None:
        self._reader.reset()
