"""`kilobot`: the Kilobot `message_t` over a serial bridge radio.

C twin: vstig_hw/_cext/framing.c (Receiver, Encoder); held equal by tests/native (index: vstig_hw/_vstig.pyi).

A Kilobot message is `{uint8 data[9]; uint8 type; uint16 crc}` (kilolib message.h)
with the CRC-16/MCRF4XX of the first 10 bytes stored little-endian. The serial
frame's payload is those 10 bytes, so the frame's CRC *is* kilolib's message CRC
and a bridge firmware forwards a received message_t unchanged:

    data[0..7] = the 8-byte wire message
    data[8]    = VSTIG_FORMAT_VERSION (0x01)
    type       = a user type below 0x80 (default 0x56, configurable)

Frames of another type are other Kilobot traffic (`foreign_type`), not ours.
"""

from __future__ import annotations

from ..counters import Counters
from ..wire import MESSAGE_SIZE, Message, decode, encode
from .base import SerialFraming
from .cobsframe import DELIMITER, CobsFrameReader, encode_frame

__all__ = ["KILOBOT_DEFAULT_TYPE", "KILOBOT_PAYLOAD_SIZE", "VSTIG_FORMAT_VERSION", "KilobotFraming",
           "check_kilobot_type", "kilobot_payload"]

KILOBOT_PAYLOAD_SIZE = 10  # data[9] + type: the bytes kilolib's CRC covers
KILOBOT_DEFAULT_TYPE = 0x56  # 'V'; user types are 0..0x7F, 0x80 and up are kilolib system commands
VSTIG_FORMAT_VERSION = 0x01


def check_kilobot_type(msg_type: int) -> int:
    if isinstance(msg_type, bool) or not isinstance(msg_type, int) or not 0 <= msg_type < 0x80:
        raise ValueError(f"Kilobot message type must be a user type in 0..127 (0x80+ are system commands), "
                         f"got {msg_type!r}")
    return msg_type


def kilobot_payload(msg: Message, msg_type: int = KILOBOT_DEFAULT_TYPE) -> bytes:
    """message_t data[9] + type carrying `msg` (the 10 bytes before the Kilobot CRC)."""
    return encode(msg) + bytes((VSTIG_FORMAT_VERSION, msg_type))


class KilobotFraming(SerialFraming):
    name = "kilobot"
    default_baud = 115200
    transmit_only = False
    preamble = DELIMITER  # sent before the first frame after the port opens (SPEC 6.0.3)

    def __init__(self, msg_type: int = KILOBOT_DEFAULT_TYPE) -> None:
        self.msg_type = check_kilobot_type(msg_type)
        self.drops = Counters()
        self._reader = CobsFrameReader(KILOBOT_PAYLOAD_SIZE, self.drops)

    def encode(self, msg: Message) -> list[bytes]:
        return [encode_frame(kilobot_payload(msg, self.msg_type))]

    def feed(self, unit: bytes) -> list[Message]:
        messages = []
        for payload in self._reader.feed(unit):
            if payload[9] != self.msg_type:
                self.drops["foreign_type"] += 1
            elif payload[8] != VSTIG_FORMAT_VERSION:
                self.drops["bad_version"] += 1
            else:
                messages.append(decode(payload[:MESSAGE_SIZE]))
        return messages

    def tick(self) -> None:
        """Nothing ages in a Kilobot stream."""

    def reset(self) -> None:
        self._reader.reset()
