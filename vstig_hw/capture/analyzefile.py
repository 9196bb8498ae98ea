"""Feed captures into an `Analyzer`: several files merged by time, a big candump log in bulk.

A single candump log goes chunk by chunk: a uniform chunk becomes columns through
`fastlog.parse_chunk` with no per-frame Python, any other chunk goes line by line
(which also names a bad line's file:line). Everything else, and several files at
once, goes record by record, merged by time.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterator, Sequence

import numpy as np

from ..analysis import NO_SENDER, Analyzer, Batch
from ..counters import Counters
from ..wire import KEY_MAX, Message
from . import candump
from .decoded import Decoder, default_framings
from .fastlog import parse_chunk, seconds
from .files import read_capture
from .records import CaptureError, Record
from .serial_log import is_serial_capture

__all__ = ["analyze_captures"]

CHUNK = 1 << 22  # bytes per candump chunk, as decode reads them


def analyze_captures(paths: Sequence[str], analyzer: Analyzer, *, skip_bad: bool = False,
                     id_base: int | None = None, extended: bool | None = None, key: int | None = None,
                     progress: Callable[[int], None] | None = None) -> tuple[Counters, list[CaptureError]]:
    """Feed every message of `paths` (only `key`'s, if given); returns (drops by reason, bad lines skipped).

    `extended=None` reads each CAN link's ID width from its frames. `progress(n)`
    hears of each n bytes read, on the bulk path.
    """
    decoder = Decoder(default_framings(id_base, extended))
    bad: list[CaptureError] = []
    if len(paths) == 1 and _bulk_readable(paths[0]) and not extended:
        drops = _candump_chunks(paths[0], analyzer, decoder, skip_bad, bad, id_base, key, progress)
        drops.update(decoder.drops())
        return drops, bad
    records = heapq.merge(*(read_capture(path, skip_bad, bad) for path in paths), key=lambda r: r.t)
    _add_records(records, analyzer, decoder, key)
    return decoder.drops(), bad


def _bulk_readable(path: str) -> bool:
    return path.endswith(".log") and not is_serial_capture(path)


def _add_records(records: Iterator[Record], analyzer: Analyzer, decoder: Decoder, key: int | None) -> None:
    def rows() -> Iterator[tuple[float, int, int, Message]]:
        links: dict[str, int] = {}
        for record in records:
            decoded = decoder.decode(record)
            if not decoded:
                continue
            link = links.get(record.link)
            if link is None:
                link = links[record.link] = analyzer.link(record.link)
            sender = decoder.sender_of(record)
            sender = NO_SENDER if sender is None else sender
            for d in decoded:
                if key is None or d.message[0] & KEY_MAX == key:
                    yield d.t, link, sender, d.message

    analyzer.add_messages(rows())


def _candump_chunks(path: str, analyzer: Analyzer, decoder: Decoder, skip_bad: bool, bad: list[CaptureError],
                    id_base: int | None, key: int | None, progress: Callable[[int], None] | None) -> Counters:
    from ..links.can import can_framing

    scheme = can_framing(id_base, False).scheme

    def classify(can_id: int) -> int | None:
        parsed = scheme.parse(can_id, False)
        return None if parsed is None else int(parsed[0])

    fast_drops: dict[str, int] = {}
    for line_no, chunk in candump.chunks(path, CHUNK):
        columns = parse_chunk(chunk, classify, fast_drops)
        if columns is None:
            _add_records(candump.chunk_records(path, chunk, line_no, skip_bad, bad), analyzer, decoder, key)
        elif len(columns.op):
            batch = Batch(seconds(columns.stamp), np.full(len(columns.op), analyzer.link(columns.link.decode())),
                          columns.can_id & scheme.max_sender, columns.op, columns.key, columns.value,
                          columns.timestamp, columns.robot)
            analyzer.add(batch if key is None else batch.where(batch.key == key))
        if progress:
            progress(len(chunk))
    return Counters(fast_drops)
