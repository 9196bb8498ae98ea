"""Our zenoh capture format (firmware_spec/SPEC.md, "Zenoh"): the serial capture's lines, plus the key.

    # vstig zenoh capture v1
    (1700000000.250000) zenoh-lab zenoh rx vstig/lab/0/201 000100640001001f

One line per sample: when it was read (or written), the link, the framing
(always `zenoh`), the direction, the key expression it was published under
(which names the sending gateway) and its payload in hex, exactly as it crossed
the network, so a capture decodes with the key space it came from and replays
sample for sample.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from typing import IO, Any

from ..framing.zenoh import ZenohSample
from .records import STRICT, Damage, Record
from .serial_log import SerialCaptureWriter, match_line, read_line_capture

__all__ = ["HEADER", "ZenohCaptureWriter", "read_zenoh_capture"]

HEADER = "# vstig zenoh capture v1"
_LINE = re.compile(r"\((\d+\.\d+)\) (\S+) (\S+) (rx|tx) (\S+) ((?:[0-9a-fA-F]{2})*)\Z")


def format_line(record: Record) -> str:
    sample: ZenohSample = record.unit
    return f"({record.t:.6f}) {record.link} {record.framing} {record.direction} {sample.key} {sample.payload.hex()}\n"


class ZenohCaptureWriter(SerialCaptureWriter):
    header = HEADER
    format_line = staticmethod(format_line)


def parse_line(path: str, number: int, line: str) -> Record | None:
    """One line of a zenoh capture; None for comments and blank lines."""
    match = match_line(path, number, line, _LINE, "zenoh capture line",
                       "(<time>) <link> zenoh rx|tx <key expression> <hex payload>")
    if match is None:
        return None
    stamp, link, framing, direction, key, data = match.groups()
    return Record(float(stamp), link, framing, ZenohSample(key, bytes.fromhex(data)), direction)


def read_zenoh_capture(path: str, damage: Damage = STRICT,
                       opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    return read_line_capture(path, parse_line, damage, opened, HEADER)
