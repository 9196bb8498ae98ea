"""candump `-l` logs (can-utils, and python-can's .log writer), one line at a time.

    (1700000000.250000) can0 600#0001000200030004
    (1700000000.250100) can0 18000001##1<up to 64 data bytes>     (CAN FD)

This per-line parser is the reference and the one that reports file:line errors;
`fastlog` decodes well-formed stretches of the same files in bulk.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Iterable, Iterator
from typing import IO, Any

import can

from .records import CAN_FRAMING, STRICT, CaptureError, Damage, Record, cut_short, parse_lines

__all__ = ["GZIP_CUT", "candump_records", "chunk_records", "chunks", "parse_line", "read_candump"]

_ERROR_FLAG = 0x20000000
GZIP_CUT = "the compressed stream has no end marker"  # what a .gz left by a killed writer lacks
_FD_LENGTHS = frozenset((0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64))


def _hex_int(text: str) -> int:
    if not text or not all(c in "0123456789abcdefABCDEF" for c in text):
        raise ValueError
    return int(text, 16)


def parse_line(path: str, number: int, line: str) -> can.Message | None:
    """The frame on one candump line (None for a blank line); CaptureError naming file:line otherwise."""
    text = line.strip()
    if not text:
        return None
    try:
        stamp, channel, frame = text.split()[:3]
        if not (stamp[0] == "(" and stamp[-1] == ")"):
            raise ValueError
        timestamp = float(stamp[1:-1])
        ident, sep, payload = frame.partition("#")
        if not sep or len(ident) not in (3, 8):
            raise ValueError
        can_id = _hex_int(ident)
        extended = len(ident) == 8
        fd = payload.startswith("#")
        flags = 0
        if fd:
            flags = _hex_int(payload[1:2])
            payload = payload[2:]
        remote = payload[:1] in ("R", "r") and not fd
        if remote:
            dlc = int(payload[1:2] or 0)
            data = b""
        else:
            payload = payload.split("_", 1)[0]  # a classic frame's optional _<len8_dlc>
            data = bytes.fromhex(payload) if len(payload) % 2 == 0 else b"\x00" * 99
            if len(data) > 8 and not (fd and len(data) in _FD_LENGTHS):
                raise ValueError
            dlc = len(data)
    except (ValueError, IndexError):
        raise CaptureError(path, number, f"not a candump line: {text[:60]!r} "
                           "(expected '(<time>) <iface> <id>#<hex data>')") from None
    return can.Message(
        timestamp=timestamp, arbitration_id=can_id & 0x1FFFFFFF, is_extended_id=extended, dlc=dlc, data=data,
        is_remote_frame=remote, is_error_frame=bool(extended and can_id & _ERROR_FLAG), is_fd=fd,
        bitrate_switch=bool(flags & 1), error_state_indicator=bool(flags & 2), channel=channel, check=False,
    )


def read_candump(path: str, damage: Damage = STRICT,
                 opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    """Records in file order (.log or .log.gz); bad lines go to `damage` (raised as CaptureError, or counted).

    `opened` is handed the file once it is open (decode's progress bar asks it how far it got).
    """
    with _open_text(path) as file:
        if opened:
            opened(file)
        kept = 0
        try:
            for record in candump_records(path, file, damage):
                kept += 1
                yield record
        except EOFError:  # a .gz whose writer was killed: every line it flushed was read
            cut_short(path, kept, "frames", GZIP_CUT, damage)
        except (OSError, zlib.error) as error:  # gzip reports a corrupt .gz this way
            raise CaptureError(path, None, f"cannot read: {error}") from None


def candump_records(path: str, lines: Iterable[str], damage: Damage, first_line: int = 1) -> Iterator[Record]:
    """The records on candump lines numbered from `first_line` (a whole file, or one chunk of it)."""
    for frame in parse_lines(path, lines, parse_line, damage, first_line):
        yield Record(frame.timestamp, str(frame.channel), CAN_FRAMING, frame)


def chunk_records(path: str, chunk: bytes, first_line: int, damage: Damage) -> Iterator[Record]:
    """The records of one chunk from `chunks`, numbered as the file numbers its lines."""
    # Split on "\n" only, as `chunks` counts lines: splitlines() also cuts at \r, \f, \x1c... and
    # would misnumber every later line in the file:line of an error.
    return candump_records(path, chunk.decode("utf-8", "replace").split("\n"), damage, first_line)


def chunks(path: str, size: int) -> Iterator[tuple[int, bytes]]:
    """(number of its first line, chunk): about `size` bytes of whole lines each (the last may lack a newline)."""
    line_no = 1
    tail = b""
    with open(path, "rb") as file:
        while True:
            block = file.read(size)
            data = tail + block
            if not block:
                tail, chunk = b"", data
            else:
                cut = data.rfind(b"\n") + 1
                tail, chunk = data[cut:], data[:cut]
            if chunk:
                yield line_no, chunk
                line_no += chunk.count(b"\n") + (0 if chunk.endswith(b"\n") else 1)
            if not block:
                return


def _open_text(path: str) -> IO[str]:
    if path.endswith(".gz"):
        import gzip

        return gzip.open(path, "rt", encoding="utf-8", errors="replace")
    return open(path, encoding="utf-8", errors="replace")
