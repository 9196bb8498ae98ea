"""Views of the raw 16-bit value: uint16, int16, float16."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.values import from_raw, to_raw


def test_int16_two_complement() -> None:
    assert from_raw(0xFFFF, "int16") == -1
    assert from_raw(0x8000, "int16") == -32768
    assert to_raw(-1, "int16") == 0xFFFF
    assert to_raw("-2", "int16") == 0xFFFE


def test_float16_ieee_half() -> None:
    assert from_raw(0x3C00, "float16") == 1.0  # IEEE 754 binary16: 1.0
    assert from_raw(0xC000, "float16") == -2.0
    assert from_raw(0x7BFF, "float16") == 65504.0  # largest finite half
    assert math.isinf(from_raw(0x7C00, "float16"))
    assert to_raw(1.5, "float16") == 0x3E00


@given(st.integers(0, 0xFFFF))
def test_int_views_round_trip(raw: int) -> None:
    for kind in ("uint16", "int16"):
        assert to_raw(from_raw(raw, kind), kind) == raw  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("value", "kind", "message"),
    [(70000, "uint16", "outside uint16"), (-1, "uint16", "outside uint16"), (40000, "int16", "outside int16"),
     (1e6, "float16", "does not fit a float16"), (1.5, "uint16", "not an integer"),
     ("1.5", "uint16", "'1.5' is not an integer"), ("abc", "int16", "'abc' is not an integer")],
)
def test_out_of_range_values_are_named(value: float, kind: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        to_raw(value, kind)  # type: ignore[arg-type]
