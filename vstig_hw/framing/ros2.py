"""ROS 2 framing: `vstig_msgs` messages in CDR, the encoding ROS 2 topics and our MCAP captures carry.

This module is the one owner of the CDR layout of `vstig_msgs/msg/Message` (op, key,
value, timestamp, robot: u8 and u16 x4; sender: i64, -1 for none; the type is
vstig_hw/ros2msgs/msg/Message.idl): little-endian CDR, a 4-byte encapsulation header,
then each field at its natural alignment. Packed with struct (~0.3 us a message, no
ROS 2 library), and held equal to rclpy's own serializer and to rosbags' by tests.

`vstig_msgs/msg/TaggedMessage` (SPEC.md 10.5) is a Message with its entry's epoch (u32) and its writer's tag
(uint8[8]) after the sender: 40 bytes of CDR against Message's 28, so a sample's size says which it is.

`Ros2Framing` turns what ROS 2 nodes publish on a gateway's `write` and `write_tagged` topics into
Messages, and the gateway's broadcasts into samples (tagged ones for `broadcast_tagged`). An untagged PUT
written with timestamp 0 ("stamp it for me") gets the timestamp after the one the gateway's table holds
for the key (`stamp`, given by the gateway), so it is newer than what the gateway
knows; a tagged one is taken as written (its tag covers its timestamp). Pure: no rclpy import; a unit is a
`Ros2Sample`.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ..auth import TAG_SIZE, Tagged
from ..counters import Counters
from ..timestamps import TS_NONE
from ..wire import KEY_MAX, Message, Op
from .base import Framing

__all__ = ["CDR_SIZE", "NO_SENDER", "TAGGED_CDR_SIZE", "Ros2Framing", "Ros2Sample", "cdr_message", "cdr_tagged",
           "message_of_cdr", "ros_name", "sender_of_wire", "tagged_of_cdr", "wire_sender"]

NO_SENDER = -1
_LE = b"\x00\x01\x00\x00"  # CDR, little-endian
# Message: the header, op, a pad byte, four u16, six pad bytes (sender's alignment), sender
_MESSAGE = struct.Struct("<4sBxHHHH6xq")
CDR_SIZE = _MESSAGE.size  # bytes of one CDR vstig_msgs/Message
# TaggedMessage: Message's fields, then epoch (u32, aligned already) and tag (8 bytes)
_TAGGED = struct.Struct(f"<4sBxHHHH6xqI{TAG_SIZE}s")
TAGGED_CDR_SIZE = _TAGGED.size
_new = tuple.__new__
_NAME_UNSAFE = re.compile(r"[^A-Za-z0-9_]")
_TWO64 = 1 << 64
_HIGH_BIT = 1 << 63


def wire_sender(sender: int | None) -> int:
    """A sender as the int64 of `vstig_msgs` (-1: none; a 64-bit XBee address from 2**63 up, which no XBee
    has, as its two's complement)."""
    return NO_SENDER if sender is None else sender - _TWO64 if sender >= _HIGH_BIT else sender


def sender_of_wire(value: int) -> int | None:
    """`wire_sender` undone."""
    return None if value == NO_SENDER else value + _TWO64 if value < 0 else value


def ros_name(text: str) -> str:
    """A valid ROS 2 name token for `text` (a link name): letters, digits, underscores; no leading digit."""
    token = _NAME_UNSAFE.sub("_", text) or "link"
    return "link_" + token if token[0].isdigit() else token


def cdr_message(message: Message, sender: int | None) -> bytes:
    """`message` as a CDR-encoded `vstig_msgs/msg/Message` (sender as `wire_sender` has it)."""
    return _MESSAGE.pack(_LE, message[0] >> 15, message[0] & KEY_MAX, message[1], message[2], message[3],
                         wire_sender(sender))


def cdr_tagged(record: Tagged, sender: int | None) -> bytes:
    """`record` as a CDR-encoded `vstig_msgs/msg/TaggedMessage`."""
    message = record.message
    return _TAGGED.pack(_LE, message[0] >> 15, message[0] & KEY_MAX, message[1], message[2], message[3],
                        wire_sender(sender), record.epoch, record.tag)


def tagged_of_cdr(data: bytes) -> tuple[Tagged, int] | None:
    """A CDR `vstig_msgs/msg/TaggedMessage` as (its record, its wire sender); None when it is not one."""
    if len(data) != _TAGGED.size or data[:4] != _LE:
        return None
    _, op, key, value, timestamp, robot, sender, epoch, tag = _TAGGED.unpack(data)
    if op > 1 or key > KEY_MAX:
        return None
    return Tagged(_new(Message, ((op << 15) | key, value, timestamp, robot)), epoch, tag), sender


def message_of_cdr(data: bytes) -> tuple[Message, int] | None:
    """A CDR `vstig_msgs/msg/Message` as (Message, its wire sender); None when it is not one (size, encoding,
    op)."""
    if len(data) != _MESSAGE.size or data[:4] != _LE:
        return None
    _, op, key, value, timestamp, robot, sender = _MESSAGE.unpack(data)
    if op > 1 or key > KEY_MAX:
        return None
    return _new(Message, ((op << 15) | key, value, timestamp, robot)), sender


@dataclass(frozen=True, slots=True)
class Ros2Sample:
    """One sample of a gateway's write topic: its CDR payload, and its publisher (a GID, hex; None: unknown)."""

    payload: bytes
    source: str | None = None


class Ros2Framing(Framing[Ros2Sample]):
    """What ROS 2 nodes write (CDR Messages) in, the gateway's broadcasts out.

    Drops (counted, never raised): `bad_cdr` (a payload that is neither a vstig_msgs/Message nor a TaggedMessage).
    `stamp(key)` gives an untagged PUT written with timestamp 0 the timestamp after the gateway's entry.
    """

    name = "ros2"
    names_sources = True  # each sample says which ROS 2 node published it
    carries_tags = True  # TaggedMessage samples (SPEC.md 10.5)

    def __init__(self, sender: int) -> None:
        self.sender = sender  # the gateway's robot id: the `sender` of what it broadcasts
        self.drops = Counters()
        self.stamp: Callable[[int], int] | None = None

    def encode(self, msg: Message) -> list[Ros2Sample]:
        return [Ros2Sample(cdr_message(msg, self.sender))]

    def encode_tagged(self, records: Sequence[Tagged]) -> list[Ros2Sample]:
        return [Ros2Sample(cdr_tagged(record, self.sender)) for record in records]

    def feed_tagged(self, unit: Ros2Sample) -> list[tuple[Message, Tagged | None]]:
        if len(unit.payload) != TAGGED_CDR_SIZE:
            return [(msg, None) for msg in self.feed(unit)]
        decoded = tagged_of_cdr(unit.payload)
        if decoded is None:
            self.drops["bad_cdr"] += 1
            return []
        return [(decoded[0].message, decoded[0])]

    def feed(self, unit: Ros2Sample) -> list[Message]:
        if len(unit.payload) == TAGGED_CDR_SIZE:  # a link with auth off: the message without its tag
            return [msg for msg, _ in self.feed_tagged(unit)]
        decoded = message_of_cdr(unit.payload)
        if decoded is None:
            self.drops["bad_cdr"] += 1
            return []
        message = decoded[0]
        if message[2] == TS_NONE and not message[0] >> 15 and self.stamp is not None:  # a PUT to stamp
            message = Message(Op.PUT, message[0], message[1], self.stamp(message[0]), message[3])
        return [message]

    def source_of(self, unit: Ros2Sample) -> str | None:
        """The publishing node (its GID): a writer may name any robot in its messages, not another's GID."""
        return unit.source

    def tick(self) -> None:
        """Samples arrive whole: nothing to expire."""
