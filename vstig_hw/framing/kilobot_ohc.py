"""`kilobot-ohc`: inject messages into a Kilobot swarm through the stock overhead controller.

The controller (kilolib ohc.c) reads fixed 132-byte packets at 38400 baud 8N1:

    byte 0       0x55 header
    byte 1       packet type: FORWARDMSG (2) repeats the message until the next
                 packet, FORWARDMSGSINGLE (6) sends it once (kilolib ohc.h enum)
    bytes 2-10   message_t data[9]
    byte 11      message_t type
    bytes 12-130 zero
    byte 131     XOR of bytes 0-130, so the whole packet XORs to 0

and adds the Kilobot CRC itself. It sends nothing back, so this framing is
transmit-only: `feed` raises TransmitOnlyError.
"""

from __future__ import annotations

from functools import reduce
from operator import xor
from typing import Literal

from ..counters import Counters
from ..wire import Message
from .base import SerialFraming
from .kilobot import KILOBOT_DEFAULT_TYPE, check_kilobot_type, kilobot_payload

__all__ = ["OHC_BAUD", "OHC_FORWARDMSG", "OHC_FORWARDMSGSINGLE", "OHC_HEADER", "OHC_PACKET_SIZE",
           "KilobotOhcFraming", "TransmitOnlyError", "ohc_packet"]

OHC_HEADER = 0x55
OHC_PACKET_SIZE = 132  # kilolib: PAGE_SIZE + 4
OHC_BAUD = 38400
OHC_FORWARDMSG = 2
OHC_FORWARDMSGSINGLE = 6
_PAD = bytes(OHC_PACKET_SIZE - 13)


class TransmitOnlyError(RuntimeError):
    """Asked to receive on a link that can only transmit."""


def ohc_packet(data_and_type: bytes, packet_type: int) -> bytes:
    """The 132-byte controller packet forwarding message_t data[9] + type."""
    body = bytes((OHC_HEADER, packet_type)) + data_and_type + _PAD
    return body + bytes((reduce(xor, body),))


class KilobotOhcFraming(SerialFraming):
    name = "kilobot-ohc"
    default_baud = OHC_BAUD
    transmit_only = True
    preamble = b""  # fixed-size packets, recognised by header and XOR: nothing to resynchronise

    def __init__(self, msg_type: int = KILOBOT_DEFAULT_TYPE, mode: Literal["single", "repeat"] = "single") -> None:
        # "single" by default: a repeating controller keeps the IR channel busy with
        # one stale message, and Kilobots' carrier sense then starves their own traffic.
        if mode not in ("single", "repeat"):
            raise ValueError(f"kilobot-ohc mode must be 'single' or 'repeat', got {mode!r}")
        self.msg_type = check_kilobot_type(msg_type)
        self.mode = mode
        self.packet_type = OHC_FORWARDMSGSINGLE if mode == "single" else OHC_FORWARDMSG
        self.drops = Counters()

    def encode(self, msg: Message) -> list[bytes]:
        return [ohc_packet(kilobot_payload(msg, self.msg_type), self.packet_type)]

    def feed(self, unit: bytes) -> list[Message]:
        raise TransmitOnlyError(
            "kilobot-ohc is transmit-only: the overhead controller sends nothing back; "
            "to hear the swarm, add a receiving link (e.g. a kilobot bridge radio)")

    def tick(self) -> None:
        """Nothing ages: packets are written whole."""

    def reset(self) -> None:
        """No receive state."""
