"""Decode a whole capture to text, JSON lines or CSV, fast where the file allows.

candump logs are read in chunks of whole lines; in a log big enough to pay for
numpy (installed with the analyze extra), a uniform chunk goes through the
vectorised `fastlog` path (JSON lines only), any other chunk line by line.
Every other capture type goes record by record through the framings.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import IO, TYPE_CHECKING, Any

from ..counters import Counters
from ..extras import missing
from ..values import ValueType
from . import candump
from .decoded import CSV_HEADER, Decoded, Decoder, as_csv, as_json, as_text, default_framings
from .files import file_position, read_capture
from .filters import Filter, RecordFilter
from .records import CaptureError
from .serial_log import is_serial_capture
from .time_columns import TimeColumn
from .zenoh_log import is_zenoh_capture

if TYPE_CHECKING:
    from .fastlog import Classify

__all__ = ["FORMATS", "decode_file"]

FORMATS = {"text": as_text, "jsonl": as_json, "csv": as_csv}
_PROGRESS_EVERY = 4096  # records between progress reports on the record-by-record path
CHUNK = 1 << 22  # bytes per candump chunk: big enough to amortise numpy, small enough for a smooth progress bar
# The smallest candump log the numpy path is taken for: loading numpy and fastlog's tables costs about
# 0.1 s, what the line-by-line path spends on some 20,000 lines (measured: the two break even near 0.8 MB).
FAST_PATH_BYTES = 1 << 20


def decode_file(path: str, out: IO[str], fmt: str = "jsonl", *, value_type: ValueType = "uint16",
                skip_bad: bool = False, id_base: int | None = None, extended: bool = False,
                progress: Callable[[int], None] | None = None, keep: Filter | None = None,
                csv_header: bool = True, file_column: bool = False, deployment: str | None = None,
                clock: TimeColumn | None = None) -> tuple[int, Counters, list[CaptureError]]:
    """Write every message in `path` that `keep` passes to `out`; returns (messages, drops, bad lines skipped).

    `progress` is told, now and then, how many bytes of the file were read so far (every format).
    CSV: `csv_header=False` leaves the header out (a later file of several); `file_column` adds a
    first column naming the file. Text: `clock` writes the time column (candump's -t styles).
    """
    formatter = _with_file(path) if fmt == "csv" and file_column else FORMATS[fmt]
    if fmt == "text" and clock is not None:
        formatter = _with_clock(clock)
    decoder = Decoder(default_framings(id_base, extended, deployment))
    bad: list[CaptureError] = []
    if fmt == "csv" and csv_header:
        out.write(("file," if file_column else "") + CSV_HEADER)
    if (path.endswith(".log") and fmt == "jsonl" and value_type == "uint16" and not extended and not keep
            and not is_serial_capture(path) and not is_zenoh_capture(path)):
        count, drops = _candump_chunks(path, out, decoder, value_type, skip_bad, bad, id_base, progress)
        drops.update(decoder.drops())
        return count, drops, bad
    count = 0
    reading: list[IO[Any]] = []
    passing = RecordFilter(keep or Filter(), decoder)
    for number, record in enumerate(read_capture(path, skip_bad, bad, reading.append)):
        for decoded in passing.messages(record)[1]:
            out.write(formatter(decoded, value_type) + "\n")
            count += 1
        if progress and number % _PROGRESS_EVERY == 0 and reading:
            progress(file_position(reading[0]) or 0)
    if progress:  # the end, also for a reader that does not show its file (MCAP)
        progress(os.path.getsize(path))
    return count, decoder.drops(), bad


def _with_clock(clock: TimeColumn) -> Callable[[Decoded, ValueType], str]:
    def line(decoded: Decoded, value_type: ValueType) -> str:
        return as_text(decoded, value_type, clock(decoded.t))

    return line


def _with_file(path: str) -> Callable[[Decoded, ValueType], str]:
    quoted = '"' + path.replace('"', '""') + '"'

    def row(decoded: Decoded, value_type: ValueType) -> str:
        return f"{quoted},{as_csv(decoded, value_type)}"

    return row


def _candump_chunks(path: str, out: IO[str], decoder: Decoder, value_type: ValueType, skip_bad: bool,
                    bad: list[CaptureError], id_base: int | None,
                    progress: Callable[[int], None] | None) -> tuple[int, Counters]:
    from ..framing.can import can_framing

    scheme = can_framing(id_base, False).scheme

    def classify(can_id: int) -> int | None:
        parsed = scheme.parse(can_id, False)
        return None if parsed is None else int(parsed[0])

    fast_drops: dict[str, int] = {}
    count = 0
    done = 0
    raw_out: Any = getattr(out, "buffer", None)
    chunk_to_jsonl = _fast_path(path)
    for line_no, chunk in candump.chunks(path, CHUNK):
        lines = chunk.count(b"\n") + (0 if chunk.endswith(b"\n") else 1)
        dropped_before = sum(fast_drops.values())
        fast = chunk_to_jsonl(chunk, classify, fast_drops) if chunk_to_jsonl else None
        if fast is not None:
            count += lines - sum(fast_drops.values()) + dropped_before
            if raw_out is not None:
                out.flush()
                raw_out.write(fast)
            else:
                out.write(fast.decode())
        else:
            count += _slow(path, chunk, line_no, out, decoder, value_type, skip_bad, bad)
        done += len(chunk)
        if progress:
            progress(done)
    return count, Counters(fast_drops)


def _fast_path(path: str) -> Callable[[bytes, Classify, dict[str, int]], bytes | None] | None:
    """fastlog's chunk decoder for a log big enough to pay for loading numpy, if numpy is installed."""
    if os.path.getsize(path) < FAST_PATH_BYTES or missing(("numpy",)):
        return None
    from .fastlog import chunk_to_jsonl

    return chunk_to_jsonl


def _slow(path: str, chunk: bytes, first_line: int, out: IO[str], decoder: Decoder, value_type: ValueType,
          skip_bad: bool, bad: list[CaptureError]) -> int:
    count = 0
    for decoded in decoder.decode_all(candump.chunk_records(path, chunk, first_line, skip_bad, bad)):
        out.write(as_json(decoded, value_type) + "\n")
        count += 1
    return count
