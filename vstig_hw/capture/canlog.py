"""CAN captures in python-can's log formats (.asc, .blf, .csv, .trc, and our .pcap registered with it).

The writer is python-can's for the extension (candump .log too); the reader is python-can's, plus
what it passes over in silence: ASC lines that are not events, a BLF cut short. ASC and BLF carry
channel numbers, named by our notes (capture.channel_names); CSV, pcap and TRC name no link.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from typing import IO, Any

import can

from .candump import GZIP_CUT
from .channel_names import BLF_APP_TEXT, ChannelNumbers, NamedBlfReader, asc_note, asc_start, blf_note, read_asc_notes
from .records import (
    APPENDABLE,
    CAN_EXTENSIONS,
    CAN_FRAMING,
    NAMELESS_EXTENSIONS,
    STRICT,
    CaptureError,
    Damage,
    Record,
    capture_suffix,
    cut_short,
)
from .writer import CaptureWriter

__all__ = ["CanCaptureWriter", "read_can_log"]

_NUMBERED_EXTENSIONS = (".asc", ".asc.gz", ".blf")  # channel numbers, named by our notes (capture.channel_names)
_BLF_CONTAINER_EVERY = 2.0  # seconds between BLF blocks written while recording


class CanCaptureWriter(CaptureWriter):
    """python-can's writer for the extension; frames keep their own timestamps, channel = link name.

    ASC and BLF number their channels: each link gets a number and a note naming it. CSV, pcap and TRC
    name no channel: a second link is refused (its frames would become the first link's).
    """

    def __init__(self, path: str, append: bool = False) -> None:
        suffix = capture_suffix(path)
        append = append and os.path.isfile(path) and os.path.getsize(path) > 0  # nothing there: a new file
        if suffix not in CAN_EXTENSIONS:
            raise ValueError(f"{path}: CAN captures are {', '.join(CAN_EXTENSIONS)} (chosen by extension)")
        if append and suffix not in APPENDABLE:
            raise ValueError(f"{path}: cannot append to a {suffix} capture (python-can can add to "
                             f"{', '.join(APPENDABLE)})")
        self.path = path
        self.writer: Any = can.Logger(path, append=True) if append else can.Logger(path)
        self._next_container = time.monotonic() + _BLF_CONTAINER_EVERY
        self._suffix = suffix
        self._numbers = ChannelNumbers()
        self._link: str | None = None  # the one link of a format that names none

    def write(self, record: Record) -> None:
        frame: can.Message = record.unit
        if frame.timestamp < 1e9:  # an interface with a monotonic clock: use the wall time we stamped
            frame.timestamp = record.t
        frame.channel = record.link
        if self._suffix in _NUMBERED_EXTENSIONS:
            frame.channel = self._numbered(record.link, frame.timestamp) - 1  # python-can counts from 0
        elif self._suffix in NAMELESS_EXTENSIONS and self._link != record.link:
            if self._link is not None:
                raise CaptureError(self.path, None, f"a {self._suffix} capture names no link: {record.link!r} "
                                   f"cannot join {self._link!r} (use .log, .asc, .blf or .mcap, or keep one --link)")
            self._link = record.link
        self.writer.on_message_received(frame)

    def _numbered(self, link: str, t: float) -> int:
        """The link's channel number, its note written before its first frame."""
        number, new = self._numbers.number(link)
        if new and isinstance(self.writer, can.BLFWriter):
            self.writer._add_object(BLF_APP_TEXT, blf_note(number, link), t)  # python-can has no public call
        elif new:
            self.writer.file.write((asc_start(t) if number == 1 else "") + asc_note(number, link))
        return number

    def size(self) -> int:
        """Bytes written so far, counting what the writer still holds (BLF: its uncompressed block)."""
        file = getattr(self.writer, "file", None)
        try:
            if hasattr(self.writer, "file_size"):
                return int(self.writer.file_size())
            return int(file.tell()) if file is not None else os.path.getsize(self.path)
        except (OSError, ValueError):
            return 0

    def flush(self) -> None:
        file = getattr(self.writer, "file", None)
        if isinstance(self.writer, can.BLFWriter):
            # BLF compresses blocks: one per tick would compress poorly, none until close would lose
            # everything to a SIGKILL. Close a block every few seconds (python-can has no public call).
            if time.monotonic() < self._next_container:
                return
            self._next_container = time.monotonic() + _BLF_CONTAINER_EVERY
            self.writer._flush()
        if file is not None and hasattr(file, "flush"):
            file.flush()

    def close(self) -> None:
        self.writer.stop()


_ASC_KEYWORDS = ("date ", "base ", "internal events", "no internal events", "begin triggerblock",
                 "end triggerblock", "//")


def _check_asc_lines(path: str, damage: Damage) -> None:
    """Lines python-can's ASC reader would pass over in silence: neither a header keyword nor a timestamped event."""
    with open(path, encoding="utf-8", errors="replace") as file:
        for number, line in enumerate(file, 1):
            text = line.strip()
            first = text.split(maxsplit=1)[0] if text else ""
            if not text or text.lower().startswith(_ASC_KEYWORDS) or first.replace(".", "", 1).isdigit():
                continue
            damage.record(CaptureError(path, number, f"not an ASC line: {text[:60]!r}"))


def _check_complete(path: str, reader: Any, frames: int) -> None:
    """A BLF names its own size in its header: a file shorter than that was cut short (python-can stops quietly)."""
    expected = getattr(reader, "file_size", 0) if isinstance(reader, can.BLFReader) else 0
    actual = os.path.getsize(path)
    if expected > actual:
        raise ValueError(f"cut short: {actual} of the {expected} bytes its header announces ({frames} records read)")


def read_can_log(path: str, damage: Damage = STRICT,
                 opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    """The frames of a capture in one of python-can's formats, as records named by link where the file names them."""
    suffix = capture_suffix(path)
    if os.path.getsize(path) == 0:
        raise CaptureError(path, None, f"empty file: not a {suffix} capture")
    if suffix == ".asc":
        _check_asc_lines(path, damage)
    frames = 0
    try:
        names: dict[int, str] = {}
        start = 0.0  # ASC: our note's exact start, to which the reader's relative times are added
        options: dict[str, Any] = {}
        if suffix.startswith(".asc"):
            notes = read_asc_notes(path)
            names, start = notes.names, notes.start or 0.0
            options["relative_timestamp"] = notes.start is not None
        reader = NamedBlfReader(path) if suffix == ".blf" else can.LogReader(path, **options)
        names = getattr(reader, "names", names)
        file = getattr(reader, "file", None)  # python-can's readers keep the open file there
        if opened and file is not None:
            opened(file)
        for frame in reader:
            frames += 1
            frame.timestamp += start
            link = names.get(frame.channel) if names and isinstance(frame.channel, int) else None
            yield Record(frame.timestamp, link or str(frame.channel or "can"), CAN_FRAMING, frame)
        _check_complete(path, reader, frames)
    except EOFError:  # an .asc.gz whose writer was killed: every line it flushed was read
        cut_short(path, frames, "frames", GZIP_CUT, damage)
    except Exception as error:  # python-can's readers raise many kinds; all mean the file is bad
        # python-can cannot resume past damage: skipped, the rest of this file is lost, and said so
        damage.record(CaptureError(path, None, f"record {frames + 1}: cannot read as {suffix}: {error}"))
