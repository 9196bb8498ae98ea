"""Buzz vstig messages: hand-worked bytes, both tag dialects, round trips, and fuzzed input never crashes."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.dialects.buzz import (
    BuzzClosure,
    BuzzDecodeError,
    BuzzOp,
    BuzzOther,
    BuzzTable,
    BuzzVstig,
    buzz_float_from_wire,
    buzz_float_to_wire,
    decode_buzz,
    encode_buzz,
)

# Worked by hand from buzzoutmsg.c/buzzvstig.c/buzztype.c: type | stig | key | value | ts | robot.
BY_HAND = [
    ("02 0001 03 0001 78 01 0000002A 0001 0005", BuzzVstig(BuzzOp.PUT, 1, "x", 42, 1, 5)),
    ("03 0001 03 0001 78 00 0000 0007", BuzzVstig(BuzzOp.QUERY, 1, "x", None, 0, 7)),
    ("02 0000 01 00000007 02 00000001 00000001 012C 0102", BuzzVstig(BuzzOp.PUT, 0, 7, 1.0, 300, 258)),
    ("02 000A 03 0003 706F73 03 0002 6162 0002 0001", BuzzVstig(BuzzOp.PUT, 10, "pos", "ab", 2, 1)),
    ("03 0001 03 0001 78 01 FFFFFFFF FFFF FFFF", BuzzVstig(BuzzOp.QUERY, 1, "x", -1, 0xFFFF, 0xFFFF)),
    ("02 0002 03 0001 6B 02 DFFFFFFF 00000002 0009 0004", BuzzVstig(BuzzOp.PUT, 2, "k", -2.5, 9, 4)),
    ("02 0002 03 0001 6B 04 01 03 0001 61 00 0001 0001",
     BuzzVstig(BuzzOp.PUT, 2, "k", BuzzTable((("a", None),)), 1, 1)),
    ("02 0002 03 0001 6B 05 01 0000002A 0001 0001", BuzzVstig(BuzzOp.PUT, 2, "k", BuzzClosure(1, 42), 1, 1)),
]
PRE2017 = [
    ("02 0001 0003 0001 78 0001 0000002A 0001 0005", BuzzVstig(BuzzOp.PUT, 1, "x", 42, 1, 5)),
    ("02 0001 0003 0001 78 0004 00000001 0003 0001 61 0000 0001 0001",
     BuzzVstig(BuzzOp.PUT, 1, "x", BuzzTable((("a", None),)), 1, 1)),
]


def _hex(spaced: str) -> bytes:
    return bytes.fromhex(spaced.replace(" ", ""))


@pytest.mark.parametrize(("spaced", "msg"), BY_HAND)
def test_current_dialect_by_hand(spaced: str, msg: BuzzVstig) -> None:
    assert decode_buzz(_hex(spaced)) == msg
    assert encode_buzz(msg) == _hex(spaced)


@pytest.mark.parametrize(("spaced", "msg"), PRE2017)
def test_pre2017_dialect_by_hand(spaced: str, msg: BuzzVstig) -> None:
    assert decode_buzz(_hex(spaced), "pre2017") == msg
    assert encode_buzz(msg, "pre2017") == _hex(spaced)
    with pytest.raises(BuzzDecodeError):  # the other dialect reads the 0x00 tag byte as nil and desyncs
        decode_buzz(_hex(spaced), "current")


@pytest.mark.parametrize(("value", "mantissa", "exponent"), [
    (1.0, 0x00000001, 1), (-2.5, -0x20000001, 2), (0.0, 0, 0), (0.1, 0x4CCCCD01, -3), (3.14159, 0x490FD001, 2),
])
def test_float_pairs(value: float, mantissa: int, exponent: int) -> None:
    assert buzz_float_to_wire(value) == (mantissa, exponent)
    single = struct.unpack("<f", struct.pack("<f", value))[0]
    assert buzz_float_from_wire(mantissa, exponent) == single


def test_other_types_are_kept_whole_and_bad_bytes_say_why() -> None:
    broadcast = _hex("00 03 0001 78 01 0000000A")
    assert decode_buzz(broadcast) == BuzzOther(0, broadcast)
    assert encode_buzz(BuzzOther(0, broadcast)) == broadcast
    for spaced, reason in [("", "buzz_empty"), ("02 0001 03 0001", "buzz_truncated"),
                           ("02 0001 06 0000 0001", "buzz_bad_type"),
                           ("02 0001 00 00 0001 0001 00", "buzz_trailing")]:
        with pytest.raises(BuzzDecodeError) as caught:
            decode_buzz(_hex(spaced))
        assert caught.value.reason == reason, spaced


def test_encoder_refuses_what_buzz_cannot_carry() -> None:
    for bad in (BuzzVstig(BuzzOp.PUT, 70000, "x", 1, 1, 1), BuzzVstig(BuzzOp.PUT, 1, "x", 1 << 31, 1, 1),
                BuzzVstig(BuzzOp.PUT, 1, "x", math.inf, 1, 1), BuzzVstig(BuzzOp.PUT, 1, "x", True, 1, 1),
                BuzzVstig(BuzzOp.PUT, 1, "a\0b", 1, 1, 1), BuzzVstig(BuzzOp.PUT, 1, "\ud800", 1, 1, 1)):
        with pytest.raises(ValueError):
            encode_buzz(bad)


float32s = st.floats(width=32, allow_nan=False, allow_infinity=False)
scalars = st.one_of(st.none(), st.integers(-(1 << 31), (1 << 31) - 1), float32s,
                    st.text(st.characters(blacklist_characters="\0", blacklist_categories=("Cs",)), max_size=20))
objects = st.recursive(scalars, lambda inner: st.lists(st.tuples(inner, inner), max_size=3).map(
    lambda items: BuzzTable(tuple(items))), max_leaves=8)
u16 = st.integers(0, 0xFFFF)
vstigs = st.builds(BuzzVstig, st.sampled_from(BuzzOp), u16, objects, objects, u16, u16)


@given(vstigs, st.sampled_from(["current", "pre2017"]))
def test_round_trip(msg: BuzzVstig, dialect: str) -> None:
    raw = encode_buzz(msg, dialect)  # type: ignore[arg-type]
    assert decode_buzz(raw, dialect) == msg  # type: ignore[arg-type]


@given(st.binary(max_size=64), st.sampled_from(["current", "pre2017"]))
def test_any_bytes_decode_or_raise_the_named_error(raw: bytes, dialect: str) -> None:
    try:
        msg = decode_buzz(raw, dialect)  # type: ignore[arg-type]
    except BuzzDecodeError as error:
        assert error.reason.startswith("buzz_")
        return
    if isinstance(msg, BuzzOther):
        assert encode_buzz(msg) == raw
    else:  # re-encoding is canonical; decoding that again is a fixed point
        assert decode_buzz(encode_buzz(msg, dialect), dialect) == msg  # type: ignore[arg-type]


@given(st.integers(-(1 << 31), (1 << 31) - 1), st.integers(-(1 << 31), (1 << 31) - 1))
def test_any_float_pair_decodes_to_a_float32(mantissa: int, exponent: int) -> None:
    value = buzz_float_from_wire(mantissa, exponent)
    assert math.isinf(value) or struct.unpack("<f", struct.pack("<f", value))[0] == value


def test_nested_tables_are_bounded() -> None:
    deep = b"\x02\x00\x01" + b"\x04\x01\x00" * 40
    with pytest.raises(BuzzDecodeError) as caught:
        decode_buzz(deep)
    assert caught.value.reason == "buzz_too_deep"
