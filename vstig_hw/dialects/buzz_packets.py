"""How Buzz transports pack messages into frames: one sender id, then [u16 length][message]...

All share the scheme; they differ in byte order, header and size:

- **BuzzKH4** (MISTLab/BuzzKH4 src/buzz/buzz_utility.c): every step a frame of exactly
  `msg_size` bytes: u16 robot id, then length-prefixed messages, zero padded; u16 in
  host order, little-endian on the Khepera IV. blabbermouth relays these frames whole.
- **ARGoS range-and-bearing** (MISTLab/Buzz src/buzz/argos/buzz_controller.cpp): the same
  with big-endian u16 (ARGoS CByteArray), `rab_data_size` bytes.
- **ROSBuzz** (MISTLab/ROSBuzz src/buzz_utility.cpp `obt_out_msg`): a block of at most 190
  bytes, u16 block length in 8-byte words, u16 robot id, length-prefixed messages, zero
  padded to whole words, all little-endian; sent as `mavros_msgs/Mavlink.payload64` after
  five header words (roscontroller.cpp `prepare_msg_and_publish`). XbeeMav
  (PacketsHandler.cpp) writes each 64-bit word big-endian, so on the radio every 8-byte
  group of the block is byte-reversed.

A zero length ends a frame. A length that runs past the frame is counted, not guessed at.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

__all__ = [
    "ROSBUZZ_BUZZ_MESSAGE",
    "ROSBUZZ_HEADER_WORDS",
    "ROSBUZZ_MAX_BLOCK",
    "BuzzFrame",
    "pack_frame",
    "pack_rosbuzz_block",
    "rosbuzz_block_from_payload64",
    "rosbuzz_payload64",
    "unpack_frame",
    "unpack_rosbuzz_block",
    "xbee_packet",
    "xbee_payload64",
    "xbee_word_order",
]

ByteOrder = Literal["little", "big"]
ROSBUZZ_MAX_BLOCK = 190  # buzz_utility.h MAX_MSG_SIZE
ROSBUZZ_HEADER_WORDS = 5  # header, ROS time, latitude, longitude, altitude
ROSBUZZ_BUZZ_MESSAGE = 2  # roscontroller.h: the header's low u16 for a Buzz block (1 is a code update)
_LEN = 2


@dataclass
class BuzzFrame:
    """A frame's sender and messages; `overrun` counts length fields that ran past the frame."""

    sender: int
    messages: list[bytes] = field(default_factory=list)
    overrun: int = 0


def _fill(out: bytearray, messages: Sequence[bytes], limit: int, order: ByteOrder) -> int:
    """Append messages while they fit in `limit` bytes; how many went in (the rest wait, in order)."""
    packed = 0
    for message in messages:
        if not message:
            raise ValueError("a Buzz message is never empty (a zero length ends the frame)")
        if len(out) + _LEN + len(message) > limit:
            break
        out += len(message).to_bytes(_LEN, order) + message
        packed += 1
    return packed


def pack_frame(sender: int, messages: Sequence[bytes], size: int, order: ByteOrder = "little") -> tuple[bytes, int]:
    """A fixed-size frame from `sender` carrying the first messages that fit; (frame, how many)."""
    if size < 2 * _LEN + 1:
        raise ValueError(f"a Buzz frame needs at least 5 bytes, got a size of {size}")
    out = bytearray(sender.to_bytes(_LEN, order))
    packed = _fill(out, messages, size, order)
    return bytes(out.ljust(size, b"\0")), packed


def _split(body: memoryview, order: ByteOrder, frame: BuzzFrame) -> BuzzFrame:
    pos = 0
    while len(body) - pos > _LEN:
        size = int.from_bytes(body[pos:pos + _LEN], order)
        pos += _LEN
        if size == 0:
            break
        if size > len(body) - pos:
            frame.overrun += 1
            break
        frame.messages.append(bytes(body[pos:pos + size]))
        pos += size
    return frame


def unpack_frame(data: bytes, order: ByteOrder = "little") -> BuzzFrame:
    """The sender id and the messages of one whole frame (KH4 or ARGoS)."""
    view = memoryview(data)
    if len(view) < _LEN:
        return BuzzFrame(sender=-1, overrun=1)
    return _split(view[_LEN:], order, BuzzFrame(int.from_bytes(view[:_LEN], order)))


def pack_rosbuzz_block(robot: int, messages: Sequence[bytes], limit: int = ROSBUZZ_MAX_BLOCK) -> tuple[bytes, int]:
    """ROSBuzz's Buzz block (whole 8-byte words, at most `limit` bytes before padding: 190 as ROSBuzz's);
    (block, how many messages)."""
    out = bytearray(4)
    out[2:4] = robot.to_bytes(2, "little")
    packed = _fill(out, messages, limit, "little")
    words = -(-len(out) // 8)
    out[0:2] = words.to_bytes(2, "little")
    return bytes(out.ljust(words * 8, b"\0")), packed


def unpack_rosbuzz_block(block: bytes) -> BuzzFrame:
    """The robot and messages of a Buzz block; its word count bounds the messages."""
    if len(block) < 4:
        return BuzzFrame(sender=-1, overrun=1)
    words, robot = struct.unpack_from("<HH", block)
    frame = BuzzFrame(robot)
    if words * 8 > len(block):
        frame.overrun += 1
        return frame
    return _split(memoryview(block)[4:words * 8], "little", frame)


def rosbuzz_payload64(block: bytes, message_number: int = 0, time_s: int = 0, time_ns: int = 0,
                      position: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> list[int]:
    """The `payload64` words ROSBuzz publishes: header, ROS time, position (doubles' bits), the block."""
    header = ROSBUZZ_BUZZ_MESSAGE | (message_number & 0xFFFF) << 16 | (time_s & 0xFFFFFFFF) << 32
    place = [struct.unpack("<Q", struct.pack("<d", x))[0] for x in position]
    return [header, time_ns, *place, *struct.unpack(f"<{len(block) // 8}Q", block)]


def rosbuzz_block_from_payload64(words: Sequence[int]) -> bytes | None:
    """The Buzz block in a `payload64`, or None when the header says it is not a Buzz message."""
    if len(words) <= ROSBUZZ_HEADER_WORDS or words[0] & 0xFFFF != ROSBUZZ_BUZZ_MESSAGE:
        return None
    return struct.pack(f"<{len(words) - ROSBUZZ_HEADER_WORDS}Q", *words[ROSBUZZ_HEADER_WORDS:])


def xbee_word_order(data: bytes) -> bytes:
    """Swap each 8-byte group's byte order: a Buzz block as XbeeMav sends it, and back (an involution)."""
    if len(data) % 8:
        raise ValueError(f"XbeeMav sends whole 64-bit words, got {len(data)} bytes")
    return b"".join(data[i:i + 8][::-1] for i in range(0, len(data), 8))


def xbee_packet(sysid: int, msgid: int, words: Sequence[int]) -> bytes:
    """XbeeMav's unfragmented packet for a Mavlink message: 'S', u8 sysid, u8 msgid, each word big-endian.

    (PacketsHandler.cpp: a serialized message under 250 bytes gets the 'S' prefix; one of
    exactly 250 bytes is never sent, longer ones are fragmented, which this does not do.)
    """
    body = bytes((sysid & 0xFF, msgid & 0xFF)) + b"".join(word.to_bytes(8, "big") for word in words)
    if len(body) >= 250:
        raise ValueError(f"XbeeMav fragments messages of 250 bytes or more; this one has {len(body)}")
    return b"S" + body


def xbee_payload64(packet: bytes) -> tuple[int, int, list[int]]:
    """(sysid, msgid, payload64 words) of an unfragmented XbeeMav packet; ValueError for anything else."""
    if len(packet) < 3 or packet[0] != ord("S") or (len(packet) - 3) % 8:
        raise ValueError("an unfragmented XbeeMav packet is 'S', sysid, msgid, then whole 64-bit words")
    words = [int.from_bytes(packet[i:i + 8], "big") for i in range(3, len(packet), 8)]
    return packet[1], packet[2], words
