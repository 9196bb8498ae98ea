"""The capture writer contract: what every format's writer does, and what a format may keep beside records.

Every writer in `records.WRITERS` subclasses `CaptureWriter` (python-can's `BaseIOHandler` is the model):
`write`, `size`, `flush` and `close` are its own; the optional call a format may offer is declared here with
the default a format without it gets, so the recorder calls it unconditionally:

* `note`: what the capture says about itself beside its records (a bridge's decisions, a capture's clock:
  capture.notes), which record readers pass over; `takes_notes` says the format keeps them (our line
  captures as comment lines, MCAP as metadata records); default: the note is not written.
"""

from __future__ import annotations

import abc
from typing import ClassVar

from .records import Record

__all__ = ["CaptureWriter"]


class CaptureWriter(abc.ABC):
    takes_notes: ClassVar[bool] = False  # True: `note` keeps a note that record readers pass over

    @abc.abstractmethod
    def write(self, record: Record) -> None:
        """Append one record."""

    @abc.abstractmethod
    def size(self) -> int:
        """Bytes in the file so far (what rotation compares with its limit)."""

    @abc.abstractmethod
    def flush(self) -> None:
        """Push what is written to the file."""

    @abc.abstractmethod
    def close(self) -> None:
        """Finish the file."""

    def note(self, text: str) -> None:
        """A note in the capture, where the format keeps them (`takes_notes`); default: not written."""
        return None
