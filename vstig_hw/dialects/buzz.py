"""Buzz's virtual-stigmergy messages: the PUT and QUERY that the Buzz VM puts in a packet.

Layout (MISTLab/Buzz src/buzz/buzzoutmsg.c `buzzoutmsg_queue_first`, buzzvstig.c
`buzzvstig_elem_serialize`; every integer big-endian, buzzmsg.c uses htons/htonl)::

    u8 type (2 PUT, 3 QUERY) | u16 stigmergy id | key object | value object | u16 timestamp | u16 robot

An object is a type tag then a body (buzztype.c `buzzobj_serialize`): nil (0, no body),
int (1, int32), float (2, Buzz's own mantissa/exponent pair of int32), string (3, u16
length + the bytes), table (4, entry count + key/value objects), closure (5, u8 native
flag + u32 function reference). Userdata (6) cannot be deserialized, so a receiver
drops such a message as malformed, and so do we.

Two dialects differ in the tag and table-count widths (commit a854c5c, 2017-07-07):
`current` (u8 tag, u8 count) and `pre2017` (u16 tag, u32 count, no closures).

Messages of other types (broadcasts, swarm lists, joins, leaves) decode to `BuzzOther`,
which keeps the bytes so a relay can pass them on untouched. A message has no length
field: the transport frames it, so decoding insists the objects end exactly there.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import Literal, TypeAlias, get_args

__all__ = [
    "BUZZ_DIALECTS",
    "BuzzClosure",
    "BuzzDecodeError",
    "BuzzDialect",
    "BuzzMessage",
    "BuzzObject",
    "BuzzOp",
    "BuzzOther",
    "BuzzTable",
    "BuzzVstig",
    "buzz_float_from_wire",
    "buzz_float_to_wire",
    "decode_buzz",
    "encode_buzz",
]

BuzzDialect = Literal["current", "pre2017"]
BUZZ_DIALECTS: tuple[str, ...] = get_args(BuzzDialect)

_NIL, _INT, _FLOAT, _STRING, _TABLE, _CLOSURE = range(6)
_MAX_DEPTH = 16  # tables inside tables: far beyond any script's, and it bounds recursion on hostile input
_MAX_MANTISSA_F = 2147483648.0  # buzzmsg.c MAX_MANTISSA (2147483646) as the float the C arithmetic turns it into
_TWO32 = 1 << 32


class BuzzOp(enum.IntEnum):
    """The vstig message types (buzzmsg.h `buzzmsg_payload_type_e`)."""

    PUT = 2
    QUERY = 3


class BuzzDecodeError(ValueError):
    """Bytes that are no Buzz message; `reason` names the drop counter."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{detail} (buzz_{reason})")
        self.reason = f"buzz_{reason}"


@dataclass(frozen=True)
class BuzzTable:
    """A Buzz table as its (key, value) pairs in wire order (a dictionary's iteration order)."""

    items: tuple[tuple[BuzzObject, BuzzObject], ...] = ()


@dataclass(frozen=True)
class BuzzClosure:
    """A serialized function: meaningful only inside the VM that sent it."""

    native: int
    ref: int


# int (int32), float (a float32 value), string, table, closure, or None for nil
BuzzObject: TypeAlias = "int | float | str | BuzzTable | BuzzClosure | None"


@dataclass(frozen=True)
class BuzzVstig:
    """One vstig PUT or QUERY. `robot` is the entry's writer, not the sender."""

    op: BuzzOp
    stigmergy: int
    key: BuzzObject
    value: BuzzObject
    timestamp: int
    robot: int


@dataclass(frozen=True)
class BuzzOther:
    """A Buzz message that is not vstig (a broadcast, a swarm message...): its bytes, kept for relaying."""

    type: int
    raw: bytes


BuzzMessage: TypeAlias = BuzzVstig | BuzzOther


# --------------------------------------------------------------------------
# Buzz's float: C float split by frexpf into a mantissa and an exponent (buzzmsg.c)
# --------------------------------------------------------------------------


def _f32(x: float) -> float:
    """`x` rounded to the nearest float32, as a C `float` holds it (overflow gives infinity)."""
    try:
        return float(struct.unpack("<f", struct.pack("<f", x))[0])
    except OverflowError:
        return math.copysign(math.inf, x)


def buzz_float_to_wire(value: float) -> tuple[int, int]:
    """The (mantissa, exponent) int32 pair `buzzmsg_serialize_float` sends for `value`.

    Buzz holds floats as C floats, so `value` is rounded to float32 first; values
    that are not finite there raise ValueError (Buzz would send undefined bytes).
    """
    single = _f32(float(value))
    if not math.isfinite(single):
        raise ValueError(f"{value!r} does not fit a Buzz float (a finite float32)")
    if single == 0.0:
        return 0, 0
    fraction, exponent = math.frexp(single)
    # (|f| - 0.5) * 2 * MAX_MANTISSA: exact in double (power-of-two scaling), truncated as C's cast does.
    mantissa = int((abs(fraction) - 0.5) * 2.0 * _MAX_MANTISSA_F) + 1
    return (-mantissa if single < 0 else mantissa), exponent


def buzz_float_from_wire(mantissa: int, exponent: int) -> float:
    """The float `buzzmsg_deserialize_float` rebuilds from the signed int32 pair, float32 rounding included."""
    if mantissa == 0:
        return 0.0
    # (float)(|m| - 1): an integer rounded to 24 significant bits, kept as an exact integer.
    q = int(_f32(float(abs(mantissa) - 1)))
    # q / 2^32 + 0.5f, rounded once to float32: the sum is (2^31 + q) / 2^32 with a 256 ulp.
    total = (1 << 31) + q
    units, rest = divmod(total, 256)
    if rest > 128 or (rest == 128 and units & 1):
        units += 1
    try:
        magnitude = _f32(math.ldexp(units * 256 / _TWO32, exponent))
    except OverflowError:
        magnitude = math.inf
    return -magnitude if mantissa < 0 else magnitude


# --------------------------------------------------------------------------
# Objects
# --------------------------------------------------------------------------


def _widths(dialect: BuzzDialect) -> tuple[int, int]:
    """(tag bytes, table count bytes) of a dialect."""
    if dialect == "current":
        return 1, 1
    if dialect == "pre2017":
        return 2, 4
    raise ValueError(f"Buzz dialect must be one of {', '.join(BUZZ_DIALECTS)}, got {dialect!r}")


def _encode_object(obj: BuzzObject, dialect: BuzzDialect, out: bytearray) -> None:
    tag_size, count_size = _widths(dialect)
    if obj is None:
        out += _NIL.to_bytes(tag_size, "big")
    elif isinstance(obj, bool):
        raise ValueError("a Buzz object cannot be a bool (Buzz has no booleans: send an int)")
    elif isinstance(obj, int):
        if not -(1 << 31) <= obj < (1 << 31):
            raise ValueError(f"{obj} does not fit a Buzz int (int32)")
        out += _INT.to_bytes(tag_size, "big") + obj.to_bytes(4, "big", signed=True)
    elif isinstance(obj, float):
        mantissa, exponent = buzz_float_to_wire(obj)
        out += _FLOAT.to_bytes(tag_size, "big") + struct.pack(">ii", mantissa, exponent)
    elif isinstance(obj, str):
        try:  # surrogateescape gives back the bytes a decoded Buzz string carried, valid UTF-8 or not
            text = obj.encode("utf-8", "surrogateescape")
        except UnicodeEncodeError:
            raise ValueError(f"a Buzz string holds UTF-8 or escaped bytes, not the lone surrogate in {obj!r}") from None
        if len(text) > 0xFFFF or 0 in text:
            raise ValueError("a Buzz string is at most 65535 bytes and holds no NUL")
        out += _STRING.to_bytes(tag_size, "big") + len(text).to_bytes(2, "big") + text
    elif isinstance(obj, BuzzTable):
        if len(obj.items) >= 1 << (8 * count_size):
            raise ValueError(f"a Buzz table holds at most {(1 << (8 * count_size)) - 1} entries in this dialect")
        out += _TABLE.to_bytes(tag_size, "big") + len(obj.items).to_bytes(count_size, "big")
        for key, value in obj.items:
            _encode_object(key, dialect, out)
            _encode_object(value, dialect, out)
    elif isinstance(obj, BuzzClosure):
        if dialect != "current":
            raise ValueError("pre-2017 Buzz cannot send closures")
        out += _CLOSURE.to_bytes(tag_size, "big") + struct.pack(">BI", obj.native, obj.ref)
    else:
        raise ValueError(f"not a Buzz object: {obj!r}")


class _Reader:
    """A cursor over one message; every read checks the bytes are there."""

    def __init__(self, data: bytes, dialect: BuzzDialect) -> None:
        self.data = data
        self.pos = 0
        self.tag_size, self.count_size = _widths(dialect)

    def take(self, size: int, what: str) -> bytes:
        end = self.pos + size
        if end > len(self.data):
            raise BuzzDecodeError("truncated", f"a Buzz message ends inside its {what} (byte {self.pos})")
        chunk = self.data[self.pos:end]
        self.pos = end
        return chunk

    def uint(self, size: int, what: str) -> int:
        return int.from_bytes(self.take(size, what), "big")

    def obj(self, what: str, depth: int = 0) -> BuzzObject:
        if depth > _MAX_DEPTH:
            raise BuzzDecodeError("too_deep", f"Buzz tables nested deeper than {_MAX_DEPTH}")
        tag = self.uint(self.tag_size, f"{what} type")
        if tag == _NIL:
            return None
        if tag == _INT:
            return int.from_bytes(self.take(4, f"{what} int"), "big", signed=True)
        if tag == _FLOAT:
            mantissa, exponent = struct.unpack(">ii", self.take(8, f"{what} float"))
            return buzz_float_from_wire(mantissa, exponent)
        if tag == _STRING:
            size = self.uint(2, f"{what} string length")
            return self.take(size, f"{what} string").decode("utf-8", "surrogateescape")
        if tag == _TABLE:
            count = self.uint(self.count_size, f"{what} table size")
            return BuzzTable(tuple((self.obj(what, depth + 1), self.obj(what, depth + 1)) for _ in range(count)))
        if tag == _CLOSURE and self.tag_size == 1:
            native, ref = struct.unpack(">BI", self.take(5, f"{what} closure"))
            return BuzzClosure(native, ref)
        raise BuzzDecodeError("bad_type", f"Buzz object type {tag} in the {what} cannot be deserialized")


# --------------------------------------------------------------------------
# Messages
# --------------------------------------------------------------------------


def decode_buzz(data: bytes | bytearray | memoryview, dialect: BuzzDialect = "current") -> BuzzMessage:
    """One Buzz message (its transport gave the length). Bad bytes raise BuzzDecodeError."""
    raw = bytes(data)
    if not raw:
        raise BuzzDecodeError("empty", "an empty Buzz message")
    if raw[0] not in (BuzzOp.PUT, BuzzOp.QUERY):
        return BuzzOther(raw[0], raw)
    reader = _Reader(raw, dialect)
    reader.pos = 1
    stigmergy = reader.uint(2, "stigmergy id")
    key = reader.obj("key")
    value = reader.obj("value")
    timestamp = reader.uint(2, "timestamp")
    robot = reader.uint(2, "robot id")
    if reader.pos != len(raw):
        raise BuzzDecodeError("trailing", f"{len(raw) - reader.pos} bytes follow a Buzz vstig message")
    return BuzzVstig(BuzzOp(raw[0]), stigmergy, key, value, timestamp, robot)


def encode_buzz(msg: BuzzMessage, dialect: BuzzDialect = "current") -> bytes:
    """The bytes of `msg`; out-of-range fields raise ValueError naming them."""
    if isinstance(msg, BuzzOther):
        return msg.raw
    for name, field in (("stigmergy", msg.stigmergy), ("timestamp", msg.timestamp), ("robot", msg.robot)):
        if isinstance(field, bool) or not isinstance(field, int) or not 0 <= field <= 0xFFFF:
            raise ValueError(f"Buzz {name} must be an integer in 0..65535, got {field!r}")
    out = bytearray((BuzzOp(msg.op),))
    out += msg.stigmergy.to_bytes(2, "big")
    _encode_object(msg.key, dialect, out)
    _encode_object(msg.value, dialect, out)
    out += msg.timestamp.to_bytes(2, "big") + msg.robot.to_bytes(2, "big")
    return bytes(out)
