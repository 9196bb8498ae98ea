"""Our serial capture format (firmware_spec/SPEC.md section 7).

    # vstig serial capture v1
    (1700000000.250000) radio0 cobs8 rx 0b0102...00

One line per chunk read from (or written to) a UART: the bytes exactly as they
crossed the wire, so a capture can be re-decoded with any framing and replayed
byte for byte.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterator
from typing import IO, Any

from ..dialects.framing import DIALECT_FRAMINGS
from ..framing import SERIAL_FRAMINGS
from .records import CaptureError, Record, parse_lines

__all__ = ["HEADER", "SerialCaptureWriter", "format_line", "read_serial_capture"]

HEADER = "# vstig serial capture v1"
_LINE = re.compile(r"\((\d+\.\d+)\) (\S+) (\S+) (rx|tx) ((?:[0-9a-fA-F]{2})+)\Z")


def format_line(record: Record) -> str:
    data: bytes = record.unit
    return f"({record.t:.6f}) {record.link} {record.framing} {record.direction} {data.hex()}\n"


class SerialCaptureWriter:
    def __init__(self, path: str, append: bool = False) -> None:
        self.path = path
        if append and os.path.isfile(path) and os.path.getsize(path) and not is_serial_capture(path):
            raise CaptureError(path, None, "cannot append: not a serial capture (its first line is not "
                               f"{HEADER!r})")
        self.file: IO[str] = open(path, "a" if append else "w", encoding="utf-8")  # noqa: SIM115 (closed by close())
        if self.file.tell() == 0:
            self.file.write(HEADER + "\n")

    def write(self, record: Record) -> None:
        self.file.write(format_line(record))

    def size(self) -> int:
        return self.file.tell()

    def flush(self) -> None:
        self.file.flush()

    def close(self) -> None:
        self.file.close()


def parse_line(path: str, number: int, line: str) -> Record | None:
    """One line of a serial capture; None for comments and blank lines."""
    text = line.rstrip("\r\n")
    if not text.strip() or text.startswith("#"):
        return None
    match = _LINE.match(text)
    if match is None:
        raise CaptureError(path, number, f"not a serial capture line: {text[:60]!r} "
                           "(expected '(<time>) <link> <framing> rx|tx <hex bytes>')")
    stamp, link, framing, direction, data = match.groups()
    if framing not in SERIAL_FRAMINGS and framing not in DIALECT_FRAMINGS:
        known = ", ".join([*SERIAL_FRAMINGS, *DIALECT_FRAMINGS])
        raise CaptureError(path, number, f"unknown serial framing {framing!r} (known: {known})")
    return Record(float(stamp), link, framing, bytes.fromhex(data), direction)


def read_serial_capture(path: str, skip_bad: bool = False, bad: list[CaptureError] | None = None,
                        opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    """Records in file order; a malformed line raises CaptureError, or with `skip_bad` is collected in `bad`."""
    with open(path, encoding="utf-8", errors="replace") as file:
        if opened:
            opened(file)
        first = file.readline()
        if first.rstrip("\r\n") != HEADER:
            raise CaptureError(path, 1, f"serial capture {first.strip()[len(_HEADER_STEM):].strip()!r} is not a "
                               f"version this vstig-hw reads (it reads {HEADER.rsplit(' ', 1)[1]})")
        yield from parse_lines(path, file, parse_line, skip_bad, bad, first_line=2)


_HEADER_STEM = HEADER.rsplit(" ", 1)[0]  # "# vstig serial capture", before the version


def is_serial_capture(path: str) -> bool:
    """The file starts like a serial capture of any version (a version we cannot read is said so on reading)."""
    with open(path, "rb") as file:
        return file.read(len(_HEADER_STEM)).decode("utf-8", "replace") == _HEADER_STEM
