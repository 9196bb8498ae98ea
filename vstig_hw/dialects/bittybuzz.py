"""BittyBuzz's 9-byte message (Kilobots, Crazyflies, Zooids) and its 16-bit float.

Layout (buzz-lang/BittyBuzz src/bittybuzz/bbzoutmsg.c `bbzoutmsg_queue_first`,
bbzinmsg.c `bbzinmsg_queue_append`; u16 in host order, little-endian on every
target, because bbzmsg.h defines htons/ntohs as the identity)::

    byte 0     type: 0 BROADCAST, 1 VSTIG_PUT, 2 VSTIG_QUERY, 3 SWARM
    bytes 1-2  rid: the entry's writer (for vstig messages)
    bytes 3-4  key: a string id of the compiled script
    byte 5     mdata: type tag in bits 0-2 (0 nil, 1 int, 2 float, 3 string),
               heap flags above it that leak onto the wire, so read `mdata & 7`
    bytes 6-7  value: int16, bbzfloat, or string id by the tag
    byte 8     lamport: 8-bit Lamport clock

A Kilobot carries the 9 bytes as `message_t.data` with `type` 2 (`BBZMSG`,
src/kilobot/lib/bbzmessage.h). Non-vstig messages decode to `BbzOther` with their bytes.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from typing import TypeAlias

__all__ = [
    "BBZ_KILOBOT_TYPE",
    "BBZ_MESSAGE_SIZE",
    "BbzDecodeError",
    "BbzMessage",
    "BbzOp",
    "BbzOther",
    "BbzType",
    "BbzVstig",
    "bbzfloat_from_float",
    "bbzfloat_to_float",
    "decode_bittybuzz",
    "encode_bittybuzz",
]

BBZ_MESSAGE_SIZE = 9
BBZ_KILOBOT_TYPE = 2  # message_t.type BBZMSG: the only type BittyBuzz's Kilobot handler reads
BBZ_TYPE_MASK = 0x07
_LAYOUT = struct.Struct("<BHHBHB")


class BbzOp(enum.IntEnum):
    """The vstig message types (bbzmsg.h `bbzmsg_payload_type_t`)."""

    PUT = 1
    QUERY = 2


class BbzType(enum.IntEnum):
    """Value type tags (bbztype.h); tables, closures and userdata are never meaningful on the wire."""

    NIL = 0
    INT = 1
    FLOAT = 2
    STRING = 3


class BbzDecodeError(ValueError):
    """Bytes that are no BittyBuzz message (only the length can be wrong)."""

    reason = "bbz_bad_length"


@dataclass(frozen=True)
class BbzVstig:
    """One vstig PUT or QUERY. `mdata` is kept whole so a relay re-sends the exact bytes."""

    op: BbzOp
    robot: int
    key: int
    mdata: int
    value: int
    lamport: int

    @property
    def value_type(self) -> int:
        """The type tag (a BbzType value for the four meaningful types)."""
        return self.mdata & BBZ_TYPE_MASK


@dataclass(frozen=True)
class BbzOther:
    """A BittyBuzz message that is not vstig (BROADCAST, SWARM, unknown): its bytes, kept for relaying."""

    type: int
    raw: bytes


BbzMessage: TypeAlias = BbzVstig | BbzOther


def decode_bittybuzz(data: bytes | bytearray | memoryview) -> BbzMessage:
    """Parse exactly 9 bytes; any other length raises BbzDecodeError naming it."""
    raw = bytes(data)
    if len(raw) != BBZ_MESSAGE_SIZE:
        raise BbzDecodeError(f"a BittyBuzz message is exactly {BBZ_MESSAGE_SIZE} bytes, got {len(raw)}")
    kind, robot, key, mdata, value, lamport = _LAYOUT.unpack(raw)
    if kind not in (BbzOp.PUT, BbzOp.QUERY):
        return BbzOther(kind, raw)
    return BbzVstig(BbzOp(kind), robot, key, mdata, value, lamport)


def encode_bittybuzz(msg: BbzMessage) -> bytes:
    """The 9 bytes of `msg`; out-of-range fields raise ValueError naming them."""
    if isinstance(msg, BbzOther):
        if len(msg.raw) != BBZ_MESSAGE_SIZE:
            raise ValueError(f"a BittyBuzz message is exactly {BBZ_MESSAGE_SIZE} bytes, got {len(msg.raw)}")
        return msg.raw
    for name, field, limit in (("robot", msg.robot, 0xFFFF), ("key", msg.key, 0xFFFF), ("mdata", msg.mdata, 0xFF),
                               ("value", msg.value, 0xFFFF), ("lamport", msg.lamport, 0xFF)):
        if isinstance(field, bool) or not isinstance(field, int) or not 0 <= field <= limit:
            raise ValueError(f"BittyBuzz {name} must be an integer in 0..{limit}, got {field!r}")
    return _LAYOUT.pack(BbzOp(msg.op), msg.robot, msg.key, msg.mdata, msg.value, msg.lamport)


# --------------------------------------------------------------------------
# bbzfloat (bbzfloat.c): sign bit 15, 6-bit exponent field E in bits 9-14, 9-bit fraction
# --------------------------------------------------------------------------


def bbzfloat_to_float(raw: int) -> float:
    """The value `bbzfloat_tofloat` gives: E 1-61 is 1.f * 2^(E-31), E 0 with a fraction 1.f * 2^-31
    (the code, not its comment's 0.f), E 62-63 infinity (a NaN is lost)."""
    if not 0 <= raw <= 0xFFFF:
        raise ValueError(f"a bbzfloat is 16 bits, got {raw!r}")
    sign = -1.0 if raw & 0x8000 else 1.0
    exponent, fraction = (raw >> 9) & 0x3F, raw & 0x1FF
    if exponent == 0 and fraction == 0:
        return sign * 0.0
    if exponent >= 62:
        return sign * math.inf
    return sign * math.ldexp(1 + fraction / 512, exponent - 31)


def bbzfloat_from_float(value: float) -> int:
    """The bbzfloat of `value`, its fraction truncated as `bbzfloat_fromfloat` does.

    Values too large (|x| >= 2^31) or not finite raise ValueError instead of becoming
    infinity. Magnitudes in [2^-31, 2^-30) use E = 0, which `bbzfloat_tofloat` reads as
    1.f * 2^-31; smaller ones become a signed zero. `bbzfloat_fromfloat` turns every
    magnitude below 2^-30 into infinity (its `e > 0 && e < 0xFF` branch also catches small
    exponents), which we do not copy.
    """
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{value!r} is not a finite number, which a bbzfloat cannot carry faithfully")
    try:
        bits: int = struct.unpack("<I", struct.pack("<f", number))[0]
    except OverflowError:
        raise ValueError(f"{value!r} does not fit a bbzfloat (|x| < 2^31)") from None
    sign = (bits >> 16) & 0x8000
    exponent = (bits >> 23) & 0xFF
    if exponent >= 158:
        raise ValueError(f"{value!r} does not fit a bbzfloat (|x| < 2^31)")
    if exponent < 96:
        return sign
    return sign | ((exponent - 96) << 9) | ((bits & 0x7FFFFF) >> 14)  # exponent 96: E=0, read back as 1.f * 2^-31
