"""Bulk candump-to-JSON-lines for well-formed stretches of a log, vectorised with numpy.

A recorded log is thousands of lines of the same shape (same interface, 3-digit
IDs, 8 data bytes). For such a chunk every field sits in the same columns, so
the chunk is one 2-D byte array: validate the punctuation and hex digits
column-wise, pull IDs and wire words out with a lookup table, and write the
output into a fixed-width template. JSON allows spaces before a number, so the
numbers are right-aligned in fixed columns and nothing is formatted per line.

Anything else (mixed shapes, 29-bit or FD frames, a malformed line) makes
`chunk_to_jsonl` return None, and the caller decodes that chunk line by line,
which also reports the file:line of a bad line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["Chunk", "chunk_to_jsonl", "parse_chunk", "seconds"]

_HEX = np.full(256, 255, dtype=np.uint8)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    _HEX[_c] = 10 + _i

Classify = Callable[[int], int | None]  # 11-bit CAN id -> the op its frames carry, or None if not ours
U8 = npt.NDArray[np.uint8]
I64 = npt.NDArray[np.int64]


def _hex(cols: U8) -> npt.NDArray[np.int64] | None:
    nibbles = _HEX[cols]
    if (nibbles == 255).any():
        return None
    wide = nibbles.astype(np.int64)
    value = wide[:, 0]
    for i in range(1, cols.shape[1]):
        value = value << 4 | wide[:, i]
    return value


def _decimal_table() -> U8:
    """Row v = the decimal digits of v (0..65535), right-aligned in 5 columns, leading spaces."""
    text = "".join(f"{v:5d}" for v in range(0x10000)).encode()
    return np.frombuffer(text, dtype=np.uint8).reshape(0x10000, 5)


_DECIMAL: U8 | None = None


_SENDER_MASK_11BIT = 0xFF  # the fast path reads 11-bit IDs only: their low byte names the sender


def _digits(out: U8, col: int, values: npt.NDArray[np.int64], width: int) -> None:
    """Right-aligned decimal digits of `values` (< 10**width, <= 65535) into out[:, col:col+width]."""
    global _DECIMAL
    if _DECIMAL is None:
        _DECIMAL = _decimal_table()
    out[:, col:col + width] = _DECIMAL[values][:, 5 - width:]


@dataclass(frozen=True)
class Chunk:
    """The frames of a uniform chunk, column by column (frames the classifier rejects already dropped)."""

    stamp: U8  # the timestamp's characters, one row per frame ("1700000000.250000")
    link: bytes  # the interface name, the same on every line
    can_id: I64
    op: I64
    key: I64
    value: I64
    timestamp: I64
    robot: I64


def chunk_to_jsonl(chunk: bytes, classify: Classify, drops: dict[str, int]) -> bytes | None:
    """JSON lines for a chunk of complete candump lines, or None if it is not uniform."""
    parsed = parse_chunk(chunk, classify, drops)
    if parsed is None:
        return None
    if not len(parsed.op):
        return b""  # every frame dropped (a bus of other traffic): nothing to render, and _render needs a row
    return _render(parsed.stamp, parsed.link, parsed.can_id, parsed.op, parsed.key, parsed.value,
                   parsed.timestamp, parsed.robot)


def seconds(stamp: U8) -> npt.NDArray[np.float64]:
    """Timestamps as float seconds from `Chunk.stamp` rows (digits around one point)."""
    point = int(np.argmax(stamp[0] == 46))
    digits = (np.delete(stamp, point, axis=1) - 48).astype(np.int64)
    whole = digits[:, :point] @ (10 ** np.arange(point - 1, -1, -1, dtype=np.int64))
    places = digits.shape[1] - point
    fraction = digits[:, point:] @ (10 ** np.arange(places - 1, -1, -1, dtype=np.int64))
    result: npt.NDArray[np.float64] = whole.astype(np.float64) + fraction / float(10**places)
    return result


def parse_chunk(chunk: bytes, classify: Classify, drops: dict[str, int]) -> Chunk | None:
    """The frames of a chunk of complete candump lines, or None if it is not uniform."""
    raw = np.frombuffer(chunk, dtype=np.uint8)
    if not len(raw) or raw[-1] != 10:
        return None
    first_nl = int(np.argmax(raw == 10))
    width = first_nl + 1
    if len(raw) % width:
        return None
    rows = raw.reshape(-1, width)
    first = bytes(rows[0])
    close = first.find(b")")
    space = first.find(b" ", close + 2)
    dot = first.find(b".")
    if not (first[:1] == b"(" and close > 2 and 1 < dot < close and first[close + 1:close + 2] == b" "
            and space > close + 2 and width == space + 22 and first[space + 4:space + 5] == b"#"):
        return None
    if not ((rows[:, width - 1] == 10).all() and (rows[:, 0] == 40).all() and (rows[:, close] == 41).all()
            and (rows[:, dot] == 46).all() and (rows[:, space + 4] == 35).all()
            and (rows[:, close + 1:space + 1] == rows[0, close + 1:space + 1]).all()):
        return None
    stamp = rows[:, 1:close]
    digits = np.delete(stamp, dot - 1, axis=1)
    if ((digits < 48) | (digits > 57)).any():
        return None
    can_id = _hex(rows[:, space + 1:space + 4])
    words = [_hex(rows[:, space + 5 + 4 * i:space + 9 + 4 * i]) for i in range(4)]
    if can_id is None or any(w is None for w in words):
        return None
    w0, w1, w2, w3 = (w for w in words if w is not None)
    op = w0 >> 15
    keep = np.ones(len(rows), dtype=bool)
    for ident in np.unique(can_id):
        expected = classify(int(ident))
        same_id = can_id == ident
        if expected is None:
            drops["unknown_id"] = drops.get("unknown_id", 0) + int(same_id.sum())
            keep &= ~same_id
        else:
            mismatch = same_id & (op != expected)
            if mismatch.any():
                drops["op_mismatch"] = drops.get("op_mismatch", 0) + int(mismatch.sum())
                keep &= ~mismatch
    if not keep.all():
        stamp = stamp[keep]
        can_id, op, w0, w1, w2, w3 = (x[keep] for x in (can_id, op, w0, w1, w2, w3))
    return Chunk(stamp, first[close + 2:space], can_id, op, w0 & 0x7FFF, w1, w2, w3)


def _render(stamp: U8, link: bytes, can_id: npt.NDArray[np.int64], op: npt.NDArray[np.int64],
            *fields: npt.NDArray[np.int64]) -> bytes:
    parts = [b'{"t":', b"STAMP", b',"link":"' + link.replace(b'"', b"") + b'","can_id":', b"CAN_ID",
             b',"op":"', b"OPS", b'","key":', b"F0", b',"value":', b"F1", b',"timestamp":', b"F2",
             b',"robot":', b"F3", b',"sender":', b"SENDER", b"}\n"]
    widths = {b"STAMP": stamp.shape[1], b"CAN_ID": 4, b"OPS": 3, b"F0": 5, b"F1": 5, b"F2": 5, b"F3": 5, b"SENDER": 3}
    # One template row (constants in place, blanks for the fields), copied to every row in one go;
    # then only the variable columns are written.
    template = b"".join(b" " * widths[p] if p in widths else p for p in parts)
    out = np.broadcast_to(np.frombuffer(template, np.uint8), (len(stamp), len(template))).copy()
    col = 0
    for part in parts:
        if part == b"STAMP":
            width = stamp.shape[1]
            out[:, col:col + width] = stamp
            integer = int(np.argmax(stamp[0] == 46))  # digits before the point
            if (stamp[:, 0] == 48).any():  # candump pads seconds with zeros; JSON numbers have none
                leading = np.cumprod(stamp[:, :integer - 1] == 48, axis=1).astype(bool)
                out[:, col:col + integer - 1][leading] = 32
        elif part == b"CAN_ID":
            _digits(out, col, can_id, 4)
        elif part == b"OPS":
            get = op == 1
            if get.any():
                out[get, col:col + 3] = np.frombuffer(b"GET", np.uint8)
            if not get.all():
                out[~get, col:col + 3] = np.frombuffer(b"PUT", np.uint8)
        elif part in (b"F0", b"F1", b"F2", b"F3"):
            _digits(out, col, fields[int(part[1:])], 5)
        elif part == b"SENDER":
            _digits(out, col, can_id & _SENDER_MASK_11BIT, 3)
        col += widths.get(part, len(part))
    return out.tobytes()
