"""Feed captures into an `Analyzer`: several files merged by time, a big candump log in bulk.

A single candump log goes chunk by chunk: a uniform chunk becomes columns through
`fastlog.parse_chunk` with no per-frame Python, any other chunk goes line by line
(which also names a bad line's file:line). Everything else, and several files at
once, goes record by record, merged by time.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import NamedTuple

import numpy as np

from ..analysis import NO_SENDER, Analyzer, Batch
from ..counters import Counters
from ..wire import Message
from . import candump
from .decoded import Decoder, RecordFilter, default_framings
from .fastlog import Chunk, parse_chunk, seconds
from .filters import Filter
from .records import STRICT, Damage, Record, read_capture, sniff

__all__ = ["Fed", "analyze_captures", "candump_parts"]

CHUNK = 1 << 22  # bytes per candump chunk, as decode reads them


class Fed(NamedTuple):
    """What reading the captures came to, beside the messages the analyzer was given."""

    drops: Counters  # units that held no stigmergy message, by reason
    filtered_out: int  # stigmergy messages the filter did not keep


def analyze_captures(paths: Sequence[str], analyzer: Analyzer, *, damage: Damage = STRICT,
                     id_base: int | None = None, extended: bool | None = None, keep: Filter | None = None,
                     progress: Callable[[int], None] | None = None,
                     deployment: str | None = None, shifts: Sequence[float] | None = None) -> Fed:
    """Feed every message of `paths` that `keep` passes.

    `extended=None` reads each CAN link's ID width from its frames. `progress(n)`
    hears of each n bytes read, on the bulk path. `shifts`: seconds to take from each
    file's times, putting captures from several PCs on one clock (clock_notes.shifts). Damage in a file
    goes to `damage` (raised, or counted and skipped).
    """
    decoder = Decoder(default_framings(id_base, extended, deployment))
    sink = _Sink(analyzer, decoder, keep or Filter())
    formats = [sniff(path) for path in paths]
    if formats == [".log"] and not extended:
        drops = _candump_chunks(paths[0], sink, damage, id_base, progress)
        drops.update(decoder.drops())
        return Fed(drops, sink.filtered_out)
    readers = [read_capture(path, damage, fmt=fmt) for path, fmt in zip(paths, formats, strict=True)]
    if shifts is not None:
        readers = [_shifted(reader, shift) if shift else reader for reader, shift in zip(readers, shifts, strict=True)]
    sink.add_records(heapq.merge(*readers, key=lambda r: r.t))
    return Fed(decoder.drops(), sink.filtered_out)


def _shifted(records: Iterable[Record], seconds: float) -> Iterator[Record]:
    for record in records:
        yield dataclasses.replace(record, t=record.t - seconds)


class _Sink:
    """Hands the analyzer what passes the filter, record by record or in batches."""

    def __init__(self, analyzer: Analyzer, decoder: Decoder, keep: Filter) -> None:
        self.analyzer = analyzer
        self.passing = RecordFilter(keep, decoder)
        self.batched_out = 0  # messages of bulk batches the filter left out (records count in `passing`)

    @property
    def filtered_out(self) -> int:
        return self.batched_out + self.passing.filtered_out

    def add_records(self, records: Iterable[Record]) -> None:
        def rows() -> Iterator[tuple[float, int, int, Message]]:
            links: dict[str, int] = {}
            for record in records:
                sender, decoded = self.passing.messages(record)
                if not decoded:
                    continue
                link = links.get(record.link)
                if link is None:
                    link = links[record.link] = self.analyzer.link(record.link)
                for d in decoded:
                    yield d.t, link, NO_SENDER if sender is None else sender, d.message

        self.analyzer.add_messages(rows())

    def add_batch(self, batch: Batch) -> None:
        if not len(batch):
            return
        keep = self.passing.keep
        if keep:
            first = float(batch.t[0])
            t0 = first - self.passing.since_start(first)
            kept = keep.mask(batch.t - t0, batch.link, self.analyzer.links, batch.sender, batch.op, batch.key,
                             batch.robot)
            self.batched_out += len(batch) - int(kept.sum())
            batch = batch.where(kept)
        self.analyzer.add(batch)


def candump_parts(path: str, id_base: int | None, damage: Damage,
                  drops: dict[str, int]) -> Iterator[tuple[int, Chunk | Iterator[Record], int]]:
    """A candump log chunk by chunk, as analyze and why read it: (bytes read, the chunk's columns where it is
    uniform else its records line by line, the mask of the sender in a CAN ID)."""
    from ..framing.can import can_framing

    scheme = can_framing(id_base, False).scheme

    def classify(can_id: int) -> int | None:
        parsed = scheme.parse(can_id, False)
        return None if parsed is None else int(parsed[0])

    for line_no, chunk in candump.chunks(path, CHUNK):
        columns = parse_chunk(chunk, classify, drops)
        yield len(chunk), candump.chunk_records(path, chunk, line_no, damage) if columns is None else columns, \
            scheme.max_sender


def _candump_chunks(path: str, sink: _Sink, damage: Damage, id_base: int | None,
                    progress: Callable[[int], None] | None) -> Counters:
    fast_drops: dict[str, int] = {}
    for size, part, max_sender in candump_parts(path, id_base, damage, fast_drops):
        if not isinstance(part, Chunk):
            sink.add_records(part)
        elif len(part.op):
            link = sink.analyzer.link(part.link.decode())
            sink.add_batch(Batch(seconds(part.stamp), np.full(len(part.op), link), part.can_id & max_sender,
                                 part.op, part.key, part.value, part.timestamp, part.robot))
        if progress:
            progress(size)
    return Counters(fast_drops)
