"""The paper's 8-byte message: the one place its layout lives.

Layout (big-endian, network order as Buzz uses)::

    byte:    0       1        2    3       4    5       6    7
         +-+---------------+ +---------+ +---------+ +---------+
         |o|      key      | |  value  | |timestamp| |  robot  |
         +-+---------------+ +---------+ +---------+ +---------+
    o = op bit (0 PUT, 1 GET); key = the low 15 bits of bytes 0-1.

`message_schema()` (construct) is the declarative definition; `encode`/`decode` are
the struct fast path for hot loops, tested equal to the schema. The schema is
built on first use: construct takes ~20 ms to import, which every `vstig`
command and simulator worker would otherwise pay. A `Message` is stored as its four wire words, so decoding is one
`struct.unpack` and no field shuffling: that is what keeps decode near the bare
struct rate.
"""

from __future__ import annotations

import enum
import functools
import struct
from operator import itemgetter
from typing import Any

__all__ = [
    "GET_BIT",
    "KEY_MAX",
    "MESSAGE_SIZE",
    "U16_MAX",
    "DecodeError",
    "Message",
    "Op",
    "check_field",
    "decode",
    "decode_many",
    "encode",
    "message_schema",
]

MESSAGE_SIZE = 8
KEY_MAX = 0x7FFF
U16_MAX = 0xFFFF
GET_BIT = 0x8000  # the op bit in a message's first wire word (`msg[0]`), for hot loops that read words


class Op(enum.IntEnum):
    PUT = 0
    GET = 1


class DecodeError(ValueError):
    """A buffer that cannot hold messages (its length is wrong)."""


@functools.cache
def message_schema() -> Any:
    """The construct BitStruct of the 8 bytes (built once, on first use)."""
    from construct import BitsInteger, BitStruct, Enum

    return BitStruct(
        "op" / Enum(BitsInteger(1), PUT=0, GET=1),
        "key" / BitsInteger(15),
        "value" / BitsInteger(16),
        "timestamp" / BitsInteger(16),
        "robot" / BitsInteger(16),
    )


_OPS = (Op.PUT, Op.GET)
_LIMITS = (("key", KEY_MAX), ("value", U16_MAX), ("timestamp", U16_MAX), ("robot", U16_MAX))


def check_field(name: str, limit: int, field: object) -> None:
    """ValueError naming `name` unless `field` is an int (not a bool) in 0..limit."""
    if isinstance(field, bool) or not isinstance(field, int) or not 0 <= field <= limit:
        raise ValueError(f"{name} must be an integer in 0..{limit}, got {field!r}")


class Message(tuple[int, int, int, int]):
    """One stigmergy message: immutable, hashable, range-checked when built.

    `Message(Op.PUT, key, value, timestamp, robot)`; read it by field name.
    Internally it is the tuple of its four big-endian wire words.
    """

    __slots__ = ()
    __match_args__ = ("op", "key", "value", "timestamp", "robot")

    def __new__(cls, op: Op | int, key: int, value: int, timestamp: int, robot: int) -> Message:
        if op not in (0, 1) or isinstance(op, bool):
            raise ValueError(f"op must be Op.PUT or Op.GET, got {op!r}")
        for (name, limit), field in zip(_LIMITS, (key, value, timestamp, robot), strict=True):
            check_field(name, limit, field)
        return tuple.__new__(cls, ((int(op) << 15) | key, value, timestamp, robot))

    @property
    def op(self) -> Op:
        return _OPS[self[0] >> 15]

    @property
    def key(self) -> int:
        return self[0] & KEY_MAX

    value: int = property(itemgetter(1))  # type: ignore[assignment]
    timestamp: int = property(itemgetter(2))  # type: ignore[assignment]
    robot: int = property(itemgetter(3))  # type: ignore[assignment]

    def replace(self, **changes: Any) -> Message:
        """A copy with some fields changed (and checked)."""
        fields = {name: getattr(self, name) for name in self.__match_args__}
        fields.update(changes)
        return Message(**fields)

    def __repr__(self) -> str:
        return (
            f"Message({self.op.name}, key={self.key}, value={self.value}, "
            f"timestamp={self.timestamp}, robot={self.robot})"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (Message, (self.op, self.key, self.value, self.timestamp, self.robot))


_STRUCT = struct.Struct(">HHHH")
_pack = _STRUCT.pack
_unpack = _STRUCT.unpack
_new = tuple.__new__


def encode(msg: Message) -> bytes:
    """The 8 wire bytes of `msg`."""
    return _pack(*msg)


def decode(data: bytes | bytearray | memoryview) -> Message:
    """Parse exactly 8 bytes; any other length raises DecodeError naming it."""
    try:
        return _new(Message, _unpack(data))
    except struct.error:
        raise DecodeError(f"a message is exactly {MESSAGE_SIZE} bytes, got {len(data)}") from None


def decode_many(data: bytes | bytearray | memoryview) -> list[Message]:
    """Messages packed back to back (CAN FD batches, bulk files), decoded in one C-level pass."""
    if len(data) % MESSAGE_SIZE:
        raise DecodeError(f"packed messages need a multiple of {MESSAGE_SIZE} bytes, got {len(data)}")
    return [_new(Message, words) for words in _STRUCT.iter_unpack(data)]


def decode_schema(data: bytes) -> Message:
    """Decode through the construct schema: slow, the reference `decode` is tested against."""
    if len(data) != MESSAGE_SIZE:
        raise DecodeError(f"a message is exactly {MESSAGE_SIZE} bytes, got {len(data)}")
    parsed = message_schema().parse(data)
    return Message(Op[str(parsed.op)], parsed.key, parsed.value, parsed.timestamp, parsed.robot)


def encode_schema(msg: Message) -> bytes:
    """Encode through the construct schema: slow, the reference `encode` is tested against."""
    fields = {"op": msg.op.name, "key": msg.key, "value": msg.value,
              "timestamp": msg.timestamp, "robot": msg.robot}
    return bytes(message_schema().build(fields))
