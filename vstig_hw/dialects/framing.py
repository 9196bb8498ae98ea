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
  (for captures: there is no live ROS link).

Counters (a link shows them as drop_<name>): `unmapped` and the guards of
`translate`, `bbz_other` for BittyBuzz messages that are not vstig (broadcasts),
`foreign_type` for Kilobot messages of another type, and the frame reader's own;
for Buzz, `buzz_other` (broadcasts and swarm messages: the robots still get them,
the relay passes every frame on), the decoder's `buzz_*` reasons, `overrun` (a
length past the frame's end) and `oversize` (a message no frame can hold: sent,
it would block the queue as it blocks BuzzKH4's).
"""

from __future__ import annotations

from typing import Literal

from ..counters import Counters
from ..framing.cobsframe import DELIMITER, CobsFrameReader, encode_frame
from ..framing.kilobot_ohc import OHC_FORWARDMSG, OHC_FORWARDMSGSINGLE, TransmitOnlyError, ohc_packet
from ..wire import Message
from .bittybuzz import BBZ_KILOBOT_TYPE, BBZ_MESSAGE_SIZE, BbzOther, decode_bittybuzz, encode_bittybuzz
from .buzz import BuzzDecodeError, BuzzOther, decode_buzz, encode_buzz
from .buzz_packets import (
    ROSBUZZ_MAX_BLOCK,
    BuzzFrame,
    pack_frame,
    pack_rosbuzz_block,
    rosbuzz_block_from_payload64,
    unpack_frame,
    unpack_rosbuzz_block,
    xbee_payload64,
)
from .mapping import Deployment
from .translate import BittyBuzzTranslator, BuzzTranslator

__all__ = ["DIALECT_FRAMINGS", "BittyBuzzKilobotFraming", "BittyBuzzOhcFraming", "BuzzKh4Framing",
           "RosBuzzDecoder", "make_dialect_framing"]

_PAYLOAD = BBZ_MESSAGE_SIZE + 1  # message_t data[9] + type: what kilolib's CRC covers


def _message_t(translator: BittyBuzzTranslator, msg: Message) -> bytes | None:
    out = translator.from_ours(msg)
    return None if out is None else encode_bittybuzz(out) + bytes((BBZ_KILOBOT_TYPE,))


class BittyBuzzKilobotFraming:
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


class BittyBuzzOhcFraming:
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


class BuzzKh4Framing:
    """Frames of `frame_size` bytes: u16 robot id, [u16 length][Buzz message]..., zero padding; little-endian."""

    name = "blabbermouth"
    transmit_only = False

    def __init__(self, deployment: Deployment, robot_id: int = 0, frame_size: int = 0xFFFF) -> None:
        self.drops = Counters()
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

    def encode_batch(self, messages: list[Message]) -> list[bytes]:
        """Buzz blocks (at most 190 bytes each) carrying our messages under our robot id."""
        pending = self._buzz_bytes(messages, ROSBUZZ_MAX_BLOCK - 2)  # its header is 4 bytes, not 2
        blocks = []
        while pending:
            block, packed = pack_rosbuzz_block(self.robot_id, pending)
            blocks.append(block)
            pending = pending[packed:]
        return blocks


DIALECT_FRAMINGS = ("bittybuzz-kilobot", "bittybuzz-ohc", "blabbermouth")  # the names their captures carry


def make_dialect_framing(name: str, deployment: Deployment) -> BittyBuzzKilobotFraming | BittyBuzzOhcFraming | \
        BuzzKh4Framing:
    """A fresh dialect framing by the name a capture records (to decode or replay it)."""
    if name == "bittybuzz-kilobot":
        return BittyBuzzKilobotFraming(deployment)
    if name == "bittybuzz-ohc":
        return BittyBuzzOhcFraming(deployment)
    if name == "blabbermouth":
        return BuzzKh4Framing(deployment)
    raise ValueError(f"unknown dialect framing {name!r}; one of {', '.join(DIALECT_FRAMINGS)}")
