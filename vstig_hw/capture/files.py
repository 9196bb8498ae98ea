"""Writing captures: the writer for each medium (`records.WRITERS`), a new numbered file past a size.

CAN: python-can's own formats, by extension (.log candump, .asc, .blf, .csv, ...), and .pcap
(vstig_hw.capture.pcap, registered with python-can by extension too), written by `canlog`.
Serial and zenoh: our line formats (`serial_log`, `zenoh_log`). Any links: rosbag2 MCAP (`rosbag`).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Protocol, cast

from .records import WRITERS, CaptureError, Record, capture_suffix, writer_class

__all__ = ["CaptureWriter", "RotatingCapture", "rotated_name"]

_SIZE_CHECK_EVERY = 64  # writes between size checks: a stat per frame would cost more than the write


class CaptureWriter(Protocol):
    def write(self, record: Record) -> None: ...
    def size(self) -> int: ...
    def flush(self) -> None: ...
    def close(self) -> None: ...


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
        if self.max_bytes and self.records % _SIZE_CHECK_EVERY == 0 and self._writer.size() >= self.max_bytes:
            with self._naming():
                self._writer.close()
            self.index += 1
            while os.path.lexists(rotated_name(self.base, self.index)):
                self.index += 1
            path = rotated_name(self.base, self.index)
            self.files.append(path)
            self._writer = self._open(path)

    def flush(self) -> None:
        """Push what is written to the file (the recorder does this every tick, so `tail -f` works)."""
        with self._naming():
            self._writer.flush()

    def close(self) -> None:
        with self._naming():
            self._writer.close()
