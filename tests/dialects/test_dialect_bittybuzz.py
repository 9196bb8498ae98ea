"""BittyBuzz's 9-byte message and bbzfloat: hand-worked bytes, round trips, fuzzed input."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.dialects.bittybuzz import (
    BbzDecodeError,
    BbzOp,
    BbzOther,
    BbzType,
    BbzVstig,
    bbzfloat_from_float,
    bbzfloat_to_float,
    decode_bittybuzz,
    encode_bittybuzz,
)

# type | rid LE | key LE | mdata | value LE | lamport, worked by hand from bbzoutmsg.c.
BY_HAND = [
    ("01 0700 2900 01 2A00 01", BbzVstig(BbzOp.PUT, 7, 41, 0x01, 42, 1)),
    ("01 0700 2900 39 2A00 01", BbzVstig(BbzOp.PUT, 7, 41, 0x39, 42, 1)),
    ("02 0300 2900 00 0000 00", BbzVstig(BbzOp.QUERY, 3, 41, 0x00, 0, 0)),
    ("01 0201 2A00 02 003E C8", BbzVstig(BbzOp.PUT, 258, 42, 0x02, 0x3E00, 200)),
    ("01 0100 2E00 01 FFFF FF", BbzVstig(BbzOp.PUT, 1, 46, 0x01, 0xFFFF, 255)),
]


@pytest.mark.parametrize(("spaced", "msg"), BY_HAND)
def test_by_hand(spaced: str, msg: BbzVstig) -> None:
    raw = bytes.fromhex(spaced.replace(" ", ""))
    assert decode_bittybuzz(raw) == msg
    assert encode_bittybuzz(msg) == raw


def test_heap_flags_do_not_change_the_type() -> None:
    assert decode_bittybuzz(bytes.fromhex("01 0700 2900 39 2A00 01".replace(" ", ""))).value_type == BbzType.INT  # type: ignore[union-attr]


def test_other_types_and_bad_lengths() -> None:
    broadcast = bytes.fromhex("00 0500 2900 01 0A00 00".replace(" ", ""))
    assert decode_bittybuzz(broadcast) == BbzOther(0, broadcast)
    for size in (0, 8, 10, 12):
        with pytest.raises(BbzDecodeError, match="exactly 9 bytes"):
            decode_bittybuzz(bytes(size))
    with pytest.raises(ValueError, match="lamport"):
        encode_bittybuzz(BbzVstig(BbzOp.PUT, 1, 1, 1, 1, 256))


@pytest.mark.parametrize(("value", "raw"), [
    (1.0, 0x3E00), (2.0, 0x4000), (0.5, 0x3C00), (-1.0, 0xBE00), (1.5, 0x3F00), (3.25, 0x4140), (0.0, 0x0000),
])
def test_bbzfloat_by_hand(value: float, raw: int) -> None:
    assert bbzfloat_from_float(value) == raw
    assert bbzfloat_to_float(raw) == value


def test_bbzfloat_edges() -> None:
    assert bbzfloat_to_float(0x0001) == math.ldexp(1 + 1 / 512, -31)  # E=0 with a fraction: 1.f, not 0.f
    assert bbzfloat_to_float(0x7C00) == math.inf and bbzfloat_to_float(0xFE01) == -math.inf  # E>=62
    assert bbzfloat_from_float(1e-12) == 0  # bbzfloat.c would say infinity here
    assert bbzfloat_from_float(-(2.0**-31) * 1.5) == 0x8100  # E=0 keeps its fraction
    for bad in (2.0**31, math.inf, math.nan, 1e40):
        with pytest.raises(ValueError):
            bbzfloat_from_float(bad)


@given(st.binary(min_size=9, max_size=9))
def test_any_nine_bytes_round_trip(raw: bytes) -> None:
    assert encode_bittybuzz(decode_bittybuzz(raw)) == raw


@given(st.integers(0, 0xFFFF))
def test_every_finite_bbzfloat_round_trips(raw: int) -> None:
    value = bbzfloat_to_float(raw)
    if (raw >> 9) & 0x3F >= 62:
        assert math.isinf(value)
    else:
        assert bbzfloat_from_float(value) == raw
