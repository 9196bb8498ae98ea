"""Framings that speak a dialect: link units <-> dialect messages <-> our Message.

Each is a serial framing like those of `vstig_hw.framing` (pure, counted), with a
translator of one deployment inside:

- `BittyBuzzKilobotFraming`: Kilobot `message_t` (data[9] = the BittyBuzz message,
  type 2) in the serial frame of a Kilobot bridge radio, as the `kilobot` framing
  carries ours;
- `BittyBuzzOhcFraming`: the same message injected through the stock overhead
  controller (transmit only);
- `BuzzKh4Framing`: BuzzKH4's fixed-size frames (a Khepera IV swarm through the
  `blabbermouth` transport), several Buzz messages per frame;
- `RosBuzzDecoder`: ROSBuzz's Buzz blocks, from `payload64` words or XbeeMav packets
  (for captures: there is no live ROS link);
- `XbeeMavFraming`: ROSBuzz drones on their XBee radios, as MISTLab's XbeeMav puts their
  blocks into XBee API frames (`S` packets, `F` fragments reassembled: dialects/xbeemav.py).

Counters (a link shows them as drop_<name>): `unmapped` and the guards of
`translate`, `bbz_other` for BittyBuzz messages that are not vstig (broadcasts),
`foreign_type` for Kilobot messages of another type, and the frame reader's own;
for Buzz, `buzz_other` (broadcasts and swarm messages: the robots still get them,
the relay passes every frame on), the decoder's `buzz_*` reasons, `overrun` (a
length past the frame's end) and `oversize` (a message no frame can hold: sent,
it would block the queue as it blocks BuzzKH4's).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Literal

from ..counters import Counters
from ..framing.base import Framing, SerialFraming
from ..framing.cobsframe import DELIMITER, CobsFrameReader, encode_frame
from ..framing.kilobot_ohc import OHC_FORWARDMSG, OHC_FORWARDMSGSINGLE, TransmitOnlyError, ohc_packet
from ..framing.xbee import BROADCAST, XBeeFraming
from ..wire import Message
from .bittybuzz import BBZ_KILOBOT_TYPE, BBZ_MESSAGE_SIZE, BbzOther, decode_bittybuzz, encode_bittybuzz
from .buzz import BuzzDecodeError, BuzzOther, decode_buzz, encode_buzz
from .buzz_packets import (
    ROSBUZZ_MAX_BLOCK,
    BuzzFrame,
    pack_frame,
    pack_rosbuzz_block,
    rosbuzz_block_from_payload64,
    rosbuzz_payload64,
    unpack_frame,
    unpack_rosbuzz_block,
    xbee_packet,
    xbee_payload64,
)
from .mapping import Deployment
from .translate import BittyBuzzTranslator, BuzzTranslator
from .xbeemav import DEFAULT_EXPIRY_TICKS, XbeeMavReassembler

__all__ = ["DIALECT_FRAMINGS", "BittyBuzzKilobotFraming", "BittyBuzzOhcFraming", "BuzzKh4Framing",
           "RosBuzzDecoder", "XbeeMavApi2Framing", "XbeeMavFraming", "make_dialect_framing"]

_PAYLOAD = BBZ_MESSAGE_SIZE + 1  # message_t data[9] + type: what kilolib's CRC covers
_HEADER_ROOM = 3 + 8 * 5  # an XbeeMav S packet's 'S', sysid and msgid, and ROSBuzz's five header words


def _message_t(translator: BittyBuzzTranslator, msg: Message) -> bytes | None:
    out = translator.from_ours(msg)
    return None if out is None else encode_bittybuzz(out) + bytes((BBZ_KILOBOT_TYPE,))


class BittyBuzzKilobotFraming(SerialFraming):
    name = "bittybuzz-kilobot"
    default_baud = 115200
    transmit_only = False
    preamble = DELIMITER  # sent before the first frame after the port opens (SPEC 6.0.3)

    def __init__(self, deployment: Deployment) -> None:
        self.drops = Counters()
        self.translator = BittyBuzzTranslator(deployment, self.drops)
        self._reader = CobsFrameReader(_PAYLOAD, self.drops)

    def encode(self, msg: Message) -> list[bytes]:
        payload = _message_t(self.translator, msg)
        return [] if payload is None else [encode_frame(payload)]

    def feed(self, unit: bytes) -> list[Message]:
        messages = []
        for payload in self._reader.feed(unit):
            if payload[BBZ_MESSAGE_SIZE] != BBZ_KILOBOT_TYPE:
                self.drops["foreign_type"] += 1
                continue
            decoded = decode_bittybuzz(payload[:BBZ_MESSAGE_SIZE])
            if isinstance(decoded, BbzOther):
                self.drops["bbz_other"] += 1
            elif (msg := self.translator.to_ours(decoded)) is not None:
                messages.append(msg)
        return messages

    def tick(self) -> None:
        """Nothing ages in a Kilobot stream."""

    def reset(self) -> None:
        self._reader.reset()


class BittyBuzzOhcFraming(SerialFraming):
    name = "bittybuzz-ohc"
    default_baud = 38400
    transmit_only = True
    preamble = b""  # fixed-size controller packets: nothing to resynchronise

    def __init__(self, deployment: Deployment, mode: Literal["single", "repeat"] = "single") -> None:
        self.drops = Counters()
        self.translator = BittyBuzzTranslator(deployment, self.drops)
        self.packet_type = OHC_FORWARDMSGSINGLE if mode == "single" else OHC_FORWARDMSG

    def encode(self, msg: Message) -> list[bytes]:
        payload = _message_t(self.translator, msg)
        return [] if payload is None else [ohc_packet(payload, self.packet_type)]

    def feed(self, unit: bytes) -> list[Message]:
        raise TransmitOnlyError("kilobot-ohc is transmit-only: the overhead controller sends nothing back; "
                                "to hear the Kilobots, add a receiving link (a kilobot bridge radio)")

    def tick(self) -> None:
        """Nothing ages: packets are written whole."""

    def reset(self) -> None:
        """No receive state."""


class BuzzKh4Framing(Framing[bytes]):
    """Frames of `frame_size` bytes: u16 robot id, [u16 length][Buzz message]..., zero padding; little-endian."""

    names_senders = True  # every frame starts with its robot's id

    name = "blabbermouth"
    transmit_only = False

    def __init__(self, deployment: Deployment, robot_id: int = 0, frame_size: int = 0xFFFF, *,
                 drops: Counters | None = None) -> None:
        self.drops = Counters() if drops is None else drops
        self.translator = BuzzTranslator(deployment, self.drops)
        self.dialect = deployment.buzz_dialect
        self.robot_id = robot_id
        self.frame_size = frame_size

    def encode(self, msg: Message) -> list[bytes]:
        return self.encode_batch([msg])

    def encode_batch(self, messages: list[Message]) -> list[bytes]:
        """As few frames as hold the messages, in order, each under our robot id (as BuzzKH4 fills its own)."""
        pending = self._buzz_bytes(messages, self.frame_size)
        frames = []
        while pending:
            frame, packed = pack_frame(self.robot_id, pending, self.frame_size, "little")
            frames.append(frame)
            pending = pending[packed:]
        return frames

    def _buzz_bytes(self, messages: list[Message], room: int) -> list[bytes]:
        """The Buzz messages for ours; one that cannot fit a frame of `room` bytes is counted, never queued."""
        out = []
        for msg in messages:
            buzz = self.translator.from_ours(msg)
            if buzz is None:
                continue
            raw = encode_buzz(buzz, self.dialect)
            if len(raw) + 4 > room:
                self.drops["oversize"] += 1
                continue
            out.append(raw)
        return out

    def feed(self, unit: bytes) -> list[Message]:
        return self._messages(unpack_frame(unit, "little"))

    def _messages(self, frame: BuzzFrame) -> list[Message]:
        self.drops["overrun"] += frame.overrun
        messages = []
        for raw in frame.messages:
            try:
                decoded = decode_buzz(raw, self.dialect)
            except BuzzDecodeError as error:
                self.drops[error.reason] += 1
                continue
            if isinstance(decoded, BuzzOther):
                self.drops["buzz_other"] += 1
            elif (msg := self.translator.to_ours(decoded)) is not None:
                messages.append(msg)
        return messages

    def sender_of(self, unit: bytes) -> int | None:
        """The robot whose frame this is (its first u16)."""
        return int.from_bytes(unit[:2], "little") if len(unit) >= 2 else None

    def tick(self) -> None:
        """Frames arrive whole: nothing ages."""

    def reset(self) -> None:
        """No partial state."""


class RosBuzzDecoder(BuzzKh4Framing):
    """ROSBuzz traffic (no live link): Buzz blocks, `payload64` words or XbeeMav packets to our Messages, and back."""

    name = "rosbuzz"

    def feed(self, unit: bytes) -> list[Message]:
        """One Buzz block (the bytes of payload64 words 5 on, little-endian)."""
        return self._messages(unpack_rosbuzz_block(unit))

    def feed_payload64(self, words: list[int]) -> list[Message]:
        """One `mavros_msgs/Mavlink.payload64` (a code-update message carries no Buzz block: nothing)."""
        block = rosbuzz_block_from_payload64(words)
        return [] if block is None else self.feed(block)

    def feed_xbee(self, packet: bytes) -> list[Message]:
        """One unfragmented XbeeMav packet ('S', sysid, msgid, big-endian words)."""
        return self.feed_payload64(xbee_payload64(packet)[2])

    def encode_batch(self, messages: list[Message], limit: int = ROSBUZZ_MAX_BLOCK) -> list[bytes]:
        """Buzz blocks (at most `limit` bytes each, 190 as ROSBuzz's) carrying our messages under our robot id."""
        pending = self._buzz_bytes(messages, limit - 2)  # its header is 4 bytes, not 2
        blocks = []
        while pending:
            block, packed = pack_rosbuzz_block(self.robot_id, pending, limit)
            blocks.append(block)
            pending = pending[packed:]
        return blocks


class XbeeMavFraming(XBeeFraming):
    """ROSBuzz's Buzz blocks in XbeeMav packets in XBee API frames (mode 1, as XbeeMav; mode 2 beside it).

    Needs the deployment that maps the swarm's Buzz keys and values (dialects/mapping.py); sends
    under `robot_id` (ROSBuzz ids are 0..255: XbeeMav's sysid is one byte). Counters as
    `XBeeFraming`'s, `RosBuzzDecoder`'s and the reassembler's, plus `xbeemav_control` (A, P, L
    packets), `xbeemav_unknown` (another first byte), `xbeemav_malformed` (a message that is not
    sysid, msgid and whole words) and `rosbuzz_other` (a Mavlink message that is no Buzz block:
    ROSBuzz's code updates).
    """

    name = "xbeemav"
    default_baud = 230400  # XbeeMav's module profiles (BD=8)
    carries_tags = False  # ROSBuzz's Buzz blocks have no room for a record
    feed_tagged = SerialFraming.feed_tagged
    encode_tagged = SerialFraming.encode_tagged
    default_max_payload = 256  # the NP of the modules XbeeMav runs on (900HP, SX), until the module says its own

    def __init__(self, deployment: Deployment, robot_id: int = 0, dest: int = BROADCAST,
                 expiry_ticks: int = DEFAULT_EXPIRY_TICKS) -> None:
        if not 0 <= robot_id <= 0xFF:
            raise ValueError(f"ROSBuzz robot ids are 0..255 (XbeeMav's sysid is one byte), got {robot_id}")
        super().__init__(dest)
        self.rosbuzz = RosBuzzDecoder(deployment, robot_id, drops=self.drops)
        self.reassembler = XbeeMavReassembler(self.drops, expiry_ticks)
        self._number = 0  # ROSBuzz's message counter: the header's and XbeeMav's msgid

    def _payloads(self, messages: Sequence[Message]) -> list[bytes]:
        """`S` packets, each a ROSBuzz Buzz block as large as ROSBuzz's 190 bytes and the module's NP allow."""
        room = (self.max_payload - _HEADER_ROOM) // 8 * 8
        packets = []
        for block in self.rosbuzz.encode_batch(list(messages), min(ROSBUZZ_MAX_BLOCK, room)):
            self._number = (self._number + 1) & 0xFFFF
            words = rosbuzz_payload64(block, self._number)  # ROS time and position: 0 (a gateway has neither)
            packets.append(xbee_packet(self.rosbuzz.robot_id, self._number, words))
        return packets

    def _messages(self, rf_data: bytes, source: int | None) -> list[Message]:
        kind = rf_data[:1]
        if kind == b"S":
            return self._buzz(rf_data[1:])
        if kind == b"F":
            whole = self.reassembler.fragment(source, rf_data)
            return [] if whole is None else self._buzz(whole)
        if kind in (b"P", b"A", b"L"):
            self.drops["xbeemav_control"] += 1
            whole = self.reassembler.ping(source, rf_data) if kind == b"P" else None
            return [] if whole is None else self._buzz(whole)
        self.drops["xbeemav_unknown"] += 1
        return []

    def _buzz(self, serialized: bytes) -> list[Message]:
        """Our messages from one serialized Mavlink message: u8 sysid, u8 msgid, big-endian words."""
        count, rest = divmod(len(serialized) - 2, 8)
        if count < 0 or rest:
            self.drops["xbeemav_malformed"] += 1
            return []
        block = rosbuzz_block_from_payload64(struct.unpack_from(f">{count}Q", serialized, 2))
        if block is None:
            self.drops["rosbuzz_other"] += 1
            return []
        return self.rosbuzz.feed(block)

    def narrow(self, unit: bytes, messages: object) -> bytes | None:
        """A frame of Buzz blocks cannot be cut to some of its messages: kept whole."""
        return unit

    def tick(self) -> None:
        super().tick()
        self.reassembler.tick()


class XbeeMavApi2Framing(XbeeMavFraming):
    """XbeeMav's packets over a module in API mode 2 (XbeeMav itself runs mode 1)."""

    name = "xbeemav-api2"
    escaped = True


# The names their captures carry, and how to make each from a deployment.
_BY_NAME: dict[str, type[BittyBuzzKilobotFraming | BittyBuzzOhcFraming | BuzzKh4Framing | XbeeMavFraming]] = {
    framing.name: framing for framing in (BittyBuzzKilobotFraming, BittyBuzzOhcFraming, BuzzKh4Framing,
                                          XbeeMavFraming, XbeeMavApi2Framing)}
DIALECT_FRAMINGS = tuple(_BY_NAME)


def make_dialect_framing(name: str, deployment: Deployment) -> BittyBuzzKilobotFraming | BittyBuzzOhcFraming | \
        BuzzKh4Framing | XbeeMavFraming:
    """A fresh dialect framing by the name a capture records (to decode or replay it)."""
    if name in _BY_NAME:
        return _BY_NAME[name](deployment)
    raise ValueError(f"unknown dialect framing {name!r}; one of {', '.join(DIALECT_FRAMINGS)}")
