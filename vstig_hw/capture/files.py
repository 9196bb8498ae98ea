"""Writing captures: the writer for each medium (`records.WRITERS`), a new numbered file past a size.

CAN: python-can's own formats, by extension (.log candump, .asc, .blf, .csv, ...), and .pcap
(vstig_hw.capture.pcap, registered with python-can by extension too), written by `canlog`.
Serial and zenoh: our line formats (`serial_log`, `zenoh_log`). Any links: rosbag2 MCAP (`rosbag`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, cast

from .records import WRITERS, CaptureError, Record, capture_suffix, writer_class
from .writer import CaptureWriter

__all__ = ["CaptureWriter", "RotatingCapture", "rotated_name"]


def rotated_name(path: str, index: int) -> str:
    """capture.log, capture_001.log, capture_002.log... (the extension stays last, so formats still match)."""
    if index == 0:
        return path
    suffix = capture_suffix(path)
    return f"{path[: len(path) - len(suffix)]}_{index:03d}{suffix}"


class RotatingCapture:
    """Writes records to `path`, starting a new numbered file whenever one exceeds `max_bytes`.

    `append` adds to an existing `path` instead of replacing it. Rotation never replaces a file: it
    moves on to the next numbered name that does not exist yet. A failed write names the file.
    `decoder` (a capture.decoded.Decoder) turns units into messages for an mcap capture.
    """

    def __init__(self, path: str, medium: str, max_bytes: int | None = None, decoder: Any = None,
                 append: bool = False) -> None:
        if medium not in WRITERS:
            *others, last = WRITERS
            raise ValueError(f"medium must be {', '.join(others)} or {last}, got {medium!r}")
        self.base, self.medium, self.max_bytes, self.decoder = path, medium, max_bytes, decoder
        self.index = 0
        self.files = [path]
        self.records = 0
        self._writer = self._open(path, append)
        self._preamble: list[str] = []  # notes each rotated file starts with
        self._in_file = 0  # records written to the current file
        self._next_check = 1  # the record count of the current file at which its size is next looked at

    def _open(self, path: str, append: bool = False) -> CaptureWriter:
        with self._naming(path):
            if self.medium == "mcap":
                if append:
                    raise ValueError(f"{path}: cannot append to an MCAP capture")
                return cast(CaptureWriter, writer_class("mcap")(path, self.decoder))
            return cast(CaptureWriter, writer_class(self.medium)(path, append))

    @contextmanager
    def _naming(self, path: str | None = None) -> Iterator[None]:
        try:
            yield
        except OSError as error:
            raise CaptureError(path or self.files[-1], None, error.strerror or str(error)) from None

    def write(self, record: Record) -> None:
        with self._naming():
            self._writer.write(record)
        self.records += 1
        self._in_file += 1
        if self.max_bytes and self._in_file >= self._next_check:
            self._check_size(self.max_bytes)

    def _check_size(self, limit: int) -> None:
        """Rotate once the file holds `limit` bytes; else plan the next look.

        The writer's size is a tell(), yet one per record costs a fifth of the write: the next look comes
        after half the records that would fill what is left at this file's mean record size, so looks
        thicken to one per record as the file nears its limit (a record over twice the mean may overshoot).
        """
        size = self._writer.size()
        if size < limit:
            mean = size / self._in_file
            self._next_check = self._in_file + max(1, int((limit - size) / (2 * mean)) if mean > 0 else 1)
            return
        with self._naming():
            self._writer.close()
        self.index += 1
        while os.path.lexists(rotated_name(self.base, self.index)):
            self.index += 1
        path = rotated_name(self.base, self.index)
        self.files.append(path)
        self._writer = self._open(path)
        self._in_file, self._next_check = 0, 1
        for text in self._preamble:
            self._writer.note(text)

    @property
    def takes_notes(self) -> bool:
        """Whether this format keeps notes (our line captures and MCAP do; CAN logs do not)."""
        return self._writer.takes_notes

    def note(self, text: str, every_file: bool = False) -> None:
        """A comment line in the capture, if its format keeps them; `every_file`: again at the top of each
        rotated file (a capture's clock)."""
        if every_file:
            self._preamble.append(text)
        with self._naming():
            self._writer.note(text)

    def flush(self) -> None:
        """Push what is written to the file (the recorder does this every tick, so `tail -f` works)."""
        with self._naming():
            self._writer.flush()

    def close(self) -> None:
        with self._naming():
            self._writer.close()
