"""Views of the raw 16-bit value field: uint16, int16 and IEEE half float.

The wire carries 16 raw bits; what they mean is the application's choice, so the
CLI lets the user pick a view (`--value-type`).
"""

from __future__ import annotations

import math
import struct
from typing import Literal, get_args

ValueType = Literal["uint16", "int16", "float16"]
VALUE_TYPES: tuple[str, ...] = get_args(ValueType)


def from_raw(raw: int, value_type: ValueType = "uint16") -> int | float:
    """Interpret the raw wire value (0..65535)."""
    if not 0 <= raw <= 0xFFFF:
        raise ValueError(f"raw value must be in 0..65535, got {raw}")
    if value_type == "uint16":
        return raw
    if value_type == "int16":
        return raw - 0x10000 if raw & 0x8000 else raw
    if value_type == "float16":
        return float(struct.unpack(">e", raw.to_bytes(2, "big"))[0])
    raise ValueError(f"value type must be one of {', '.join(VALUE_TYPES)}, got {value_type!r}")


def to_raw(value: int | float | str, value_type: ValueType = "uint16") -> int:
    """The raw wire value for `value` seen as `value_type`; out-of-range values raise ValueError."""
    if value_type == "float16":
        number = float(value)
        try:
            packed = struct.pack(">e", number)
        except OverflowError:
            raise ValueError(f"{value} does not fit a float16 (|x| <= 65504)") from None
        if math.isfinite(number) and not math.isfinite(struct.unpack(">e", packed)[0]):
            raise ValueError(f"{value} does not fit a float16 (|x| <= 65504)")
        return int.from_bytes(packed, "big")
    try:
        number_i = int(value, 0) if isinstance(value, str) else value
    except ValueError:  # int()'s own message ("invalid literal ... base 0") says nothing to a user
        raise ValueError(f"{value!r} is not an integer, as {value_type} needs (e.g. 1500 or 0x5dc)") from None
    if isinstance(number_i, float):
        if not number_i.is_integer():
            raise ValueError(f"{value} is not an integer, as {value_type} needs")
        number_i = int(number_i)
    if value_type == "uint16":
        if not 0 <= number_i <= 0xFFFF:
            raise ValueError(f"{value} is outside uint16 range 0..65535")
        return number_i
    if value_type == "int16":
        if not -0x8000 <= number_i <= 0x7FFF:
            raise ValueError(f"{value} is outside int16 range -32768..32767")
        return number_i & 0xFFFF
    raise ValueError(f"value type must be one of {', '.join(VALUE_TYPES)}, got {value_type!r}")
