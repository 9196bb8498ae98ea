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
from .records import STRICT, CaptureError, Damage, Record, parse_lines
from .writer import CaptureWriter

__all__ = ["HEADER", "SerialCaptureWriter", "format_line", "read_serial_capture"]

HEADER = "# vstig serial capture v1"
_LINE = re.compile(r"\((\d+\.\d+)\) (\S+) (\S+) (rx|tx) ((?:[0-9a-fA-F]{2})+)\Z")


def format_line(record: Record) -> str:
    data: bytes = record.unit
    return f"({record.t:.6f}) {record.link} {record.framing} {record.direction} {data.hex()}\n"


class SerialCaptureWriter(CaptureWriter):
    """A line capture: a header line, then one line per record (the zenoh capture shares it)."""

    takes_notes = True
    header = HEADER
    format_line = staticmethod(format_line)

    def __init__(self, path: str, append: bool = False) -> None:
        self.path = path
        if append and os.path.isfile(path) and os.path.getsize(path) and not is_serial_capture(path, self.header):
            raise CaptureError(path, None, f"cannot append: not a {_kind(self.header)} (its first line is not "
                               f"{self.header!r})")
        self.file: IO[str] = open(path, "a" if append else "w", encoding="utf-8")  # noqa: SIM115 (closed by close())
        if self.file.tell() == 0:
            self.file.write(self.header + "\n")

    def write(self, record: Record) -> None:
        self.file.write(self.format_line(record))

    def note(self, text: str) -> None:
        """A comment line (`# text`) that readers skip: what the capture says about itself (clock_notes)."""
        self.file.write(f"# {text}\n")

    def size(self) -> int:
        return self.file.tell()

    def flush(self) -> None:
        self.file.flush()

    def close(self) -> None:
        self.file.close()


def match_line(path: str, number: int, line: str, pattern: re.Pattern[str], what: str,
               expected: str) -> re.Match[str] | None:
    """A capture line's fields; None for comments and blank lines; CaptureError naming `what` it should be."""
    text = line.rstrip("\r\n")
    if not text.strip() or text.startswith("#"):
        return None
    match = pattern.match(text)
    if match is None:
        raise CaptureError(path, number, f"not a {what}: {text[:60]!r} (expected {expected!r})")
    return match


def parse_line(path: str, number: int, line: str) -> Record | None:
    """One line of a serial capture; None for comments and blank lines."""
    match = match_line(path, number, line, _LINE, "serial capture line", "(<time>) <link> <framing> rx|tx <hex bytes>")
    if match is None:
        return None
    stamp, link, framing, direction, data = match.groups()
    if framing not in SERIAL_FRAMINGS and framing not in DIALECT_FRAMINGS:
        known = ", ".join([*SERIAL_FRAMINGS, *DIALECT_FRAMINGS])
        raise CaptureError(path, number, f"unknown serial framing {framing!r} (known: {known})")
    return Record(float(stamp), link, framing, bytes.fromhex(data), direction)


def read_line_capture(path: str, parse: Callable[[str, int, str], Record | None], damage: Damage = STRICT,
                      opened: Callable[[IO[Any]], None] | None = None, header: str = HEADER) -> Iterator[Record]:
    """Records in file order; a malformed line goes to `damage` (raised as CaptureError, or counted).

    `opened` is handed the file once it is open, so a caller can tell how far reading got.
    A first line other than `header` (another version) is refused, naming the version.
    """
    with open(path, encoding="utf-8", errors="replace") as file:
        if opened:
            opened(file)
        first = file.readline()
        if first.rstrip("\r\n") != header:
            stem = _stem(header)
            raise CaptureError(path, 1, f"{_kind(header)} {first.strip()[len(stem):].strip()!r} is not a version "
                               f"this vstig-hw reads (it reads {header.rsplit(' ', 1)[1]})")
        yield from parse_lines(path, file, parse, damage, first_line=2)


def read_serial_capture(path: str, damage: Damage = STRICT,
                        opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    return read_line_capture(path, parse_line, damage, opened, HEADER)


def _stem(header: str) -> str:
    """'# vstig serial capture', the header before its version."""
    return header.rsplit(" ", 1)[0]


def _kind(header: str) -> str:
    """'serial capture', for messages."""
    return _stem(header).removeprefix("# vstig ")


def is_serial_capture(path: str, header: str = HEADER) -> bool:
    """The file starts like a capture of `header`'s kind, any version (reading names a version it cannot read)."""
    stem = _stem(header)
    with open(path, "rb") as file:
        return file.read(len(stem)).decode("utf-8", "replace") == stem
