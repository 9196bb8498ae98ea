"""Capture files chosen by extension: writers (with rotation by size) and readers.

CAN: python-can's own formats, by extension (.log candump, .asc, .blf, .csv, ...), and .pcap
(vstig_hw.capture.pcap, registered with python-can by extension too).
Serial: our line format (`serial_log`). A reader tells them apart by the
serial header, then by extension.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Protocol

import can

from .candump import GZIP_CUT, read_candump
from .channel_names import BLF_APP_TEXT, ChannelNumbers, NamedBlfReader, asc_note, asc_start, blf_note, read_asc_notes
from .records import CAN_FRAMING, CaptureError, Record, cut_short
from .serial_log import SerialCaptureWriter, is_serial_capture, read_serial_capture
from .zenoh_log import ZenohCaptureWriter, is_zenoh_capture, read_zenoh_capture

__all__ = ["APPENDABLE", "CAN_EXTENSIONS", "MCAP_EXTENSION", "NAMELESS_EXTENSIONS", "READABLE_EXTENSIONS",
           "CaptureWriter", "RotatingCapture", "capture_suffix", "file_position", "link_names_lost", "read_capture",
           "rotated_name", "sniff_suffix"]

CAN_EXTENSIONS = (".log", ".asc", ".blf", ".csv", ".pcap", ".trc", ".log.gz", ".asc.gz")
MCAP_EXTENSION = ".mcap"  # rosbag2 MCAP (capture.rosbag): decoded messages of any links
READ_ONLY_EXTENSIONS = (".pcapng",)  # formats we read but do not write (Wireshark's default)
READABLE_EXTENSIONS = (*CAN_EXTENSIONS, *READ_ONLY_EXTENSIONS, MCAP_EXTENSION)
APPENDABLE = (".log", ".blf", ".csv", ".log.gz")  # the CAN formats python-can's writers can add to
NAMELESS_EXTENSIONS = (".csv", ".pcap", ".trc")  # CAN formats with no channel or name: one link, unnamed
_NUMBERED_EXTENSIONS = (".asc", ".asc.gz", ".blf")  # channel numbers, named by our notes (capture.channel_names)
_BLF_CONTAINER_EVERY = 2.0  # seconds between BLF blocks written while recording


class CaptureWriter(Protocol):
    def write(self, record: Record) -> None: ...
    def size(self) -> int: ...
    def flush(self) -> None: ...
    def close(self) -> None: ...


def _suffix(path: str) -> str:
    suffixes = Path(path).suffixes
    return "".join(suffixes[-2:]).lower() if suffixes[-1:] == [".gz"] else "".join(suffixes[-1:]).lower()


def capture_suffix(path: str) -> str:
    """The extension that tells a capture's format: `.log`, `.log.gz`... (lower case)."""
    return _suffix(path)


def link_names_lost(path: str) -> bool:
    """Whether a CAN capture at `path` names no link (CSV, pcap, TRC): it can hold only one, unnamed."""
    return _suffix(path) in NAMELESS_EXTENSIONS


class CanCaptureWriter:
    """python-can's writer for the extension; frames keep their own timestamps, channel = link name.

    ASC and BLF number their channels: each link gets a number and a note naming it. CSV, pcap and TRC
    name no channel: a second link is refused (its frames would become the first link's).
    """

    def __init__(self, path: str, append: bool = False) -> None:
        suffix = _suffix(path)
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


_WRITERS: dict[str, Callable[[str, bool], CaptureWriter]] = {
    "can": CanCaptureWriter, "serial": SerialCaptureWriter, "zenoh": ZenohCaptureWriter,
}

_PCAP_MAGICS = tuple(m.to_bytes(4, order) for m in (0xA1B2C3D4, 0xA1B23C4D) for order in ("big", "little"))


_ASC_KEYWORDS = ("date ", "base ", "internal events", "no internal events", "begin triggerblock",
                 "end triggerblock", "//")


def _check_asc_lines(path: str, skip_bad: bool, bad: list[CaptureError] | None) -> None:
    """Lines python-can's ASC reader would pass over in silence: neither a header keyword nor a timestamped event."""
    with open(path, encoding="utf-8", errors="replace") as file:
        for number, line in enumerate(file, 1):
            text = line.strip()
            first = text.split(maxsplit=1)[0] if text else ""
            if not text or text.lower().startswith(_ASC_KEYWORDS) or first.replace(".", "", 1).isdigit():
                continue
            error = CaptureError(path, number, f"not an ASC line: {text[:60]!r}")
            if not skip_bad:
                raise error
            if bad is not None:
                bad.append(error)


def _check_complete(path: str, reader: Any, frames: int) -> None:
    """A BLF names its own size in its header: a file shorter than that was cut short (python-can stops quietly)."""
    expected = getattr(reader, "file_size", 0) if isinstance(reader, can.BLFReader) else 0
    actual = os.path.getsize(path)
    if expected > actual:
        raise ValueError(f"cut short: {actual} of the {expected} bytes its header announces ({frames} records read)")


def sniff_suffix(head: bytes) -> str | None:
    """The capture type a file's first bytes show, as its extension (for a stream with no name to go by)."""
    if head.startswith((b"# vstig serial capture", b"# vstig zenoh capture")):  # found by header, any name
        return ".cap"
    if head.startswith(b"LOGG"):
        return ".blf"
    if head[:4] in _PCAP_MAGICS:
        return ".pcap"
    if head.startswith(b"\x0a\x0d\x0d\x0a"):
        return ".pcapng"
    if head.startswith(b"\x89MCAP"):
        return MCAP_EXTENSION
    if head.startswith(b"\x1f\x8b"):
        return ".log.gz"
    text = head.lstrip()
    for start, suffix in ((b"(", ".log"), (b"date ", ".asc"), (b"base ", ".asc"), (b"timestamp,", ".csv"),
                          (b";$FILEVERSION", ".trc")):
        if text.startswith(start):
            return suffix
    return None


def file_position(file: IO[Any]) -> int | None:
    """How many bytes of the file on disk were read so far (compressed bytes for .gz); None for a pipe."""
    try:
        return os.lseek(file.fileno(), 0, os.SEEK_CUR)
    except (OSError, ValueError, AttributeError):
        return None


def rotated_name(path: str, index: int) -> str:
    """capture.log, capture_001.log, capture_002.log... (the extension stays last, so formats still match)."""
    if index == 0:
        return path
    suffix = _suffix(path)
    return f"{path[: len(path) - len(suffix)]}_{index:03d}{suffix}"


class RotatingCapture:
    """Writes records to `path`, starting a new numbered file whenever one exceeds `max_bytes`.

    `append` adds to an existing `path` instead of replacing it. Rotation never replaces a file: it
    moves on to the next numbered name that does not exist yet. A failed write names the file.
    `decoder` (a capture.decoded.Decoder) turns units into messages for an mcap capture.
    """

    def __init__(self, path: str, medium: str, max_bytes: int | None = None, decoder: Any = None,
                 append: bool = False) -> None:
        if medium not in (*_WRITERS, "mcap"):
            raise ValueError(f"medium must be {', '.join(_WRITERS)} or mcap, got {medium!r}")
        self.base, self.medium, self.max_bytes, self.decoder = path, medium, max_bytes, decoder
        self.index = 0
        self.files = [path]
        self.records = 0
        self._writer = self._open(path, append)
        self._in_file = 0  # records written to the current file
        self._next_check = 1  # the record count of the current file at which its size is next looked at

    def _open(self, path: str, append: bool = False) -> CaptureWriter:
        with self._naming(path):
            if self.medium == "mcap":
                if append:
                    raise ValueError(f"{path}: cannot append to an MCAP capture")
                from .rosbag import McapCaptureWriter

                return McapCaptureWriter(path, self.decoder)
            return _WRITERS[self.medium](path, append)

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

    def flush(self) -> None:
        """Push what is written to the file (the recorder does this every tick, so `tail -f` works)."""
        with self._naming():
            self._writer.flush()

    def close(self) -> None:
        with self._naming():
            self._writer.close()


def read_capture(path: str, skip_bad: bool = False, bad: list[CaptureError] | None = None,
                 opened: Callable[[IO[Any]], None] | None = None) -> Iterator[Record]:
    """Every record of a capture: ours (serial, zenoh), candump logs, or any python-can format.

    `opened` is handed the file being read once it is open, so a caller can tell how far reading got
    (`file_position`).
    """
    if not os.path.isfile(path):
        raise CaptureError(path, None, "no such file")
    if is_serial_capture(path):
        yield from read_serial_capture(path, skip_bad, bad, opened)
        return
    if is_zenoh_capture(path):
        yield from read_zenoh_capture(path, skip_bad, bad, opened)
        return
    suffix = _suffix(path)
    if suffix == MCAP_EXTENSION:
        from .rosbag import read_mcap

        yield from read_mcap(path, skip_bad, bad)
        return
    if suffix in (".log", ".log.gz"):
        yield from read_candump(path, skip_bad, bad, opened)
        return
    if suffix not in READABLE_EXTENSIONS:
        raise CaptureError(path, None, f"unknown capture type {suffix or '(no extension)'!r}: expected a "
                           f"serial capture or one of {', '.join(READABLE_EXTENSIONS)}")
    if os.path.getsize(path) == 0:
        raise CaptureError(path, None, f"empty file: not a {suffix} capture")
    if suffix == ".asc":
        _check_asc_lines(path, skip_bad, bad)
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
        cut_short(path, frames, "frames", GZIP_CUT, skip_bad, bad)
    except Exception as error:  # python-can's readers raise many kinds; all mean the file is bad
        damage = CaptureError(path, None, f"record {frames + 1}: cannot read as {suffix}: {error}")
        if not skip_bad:
            raise damage from None
        if bad is not None:  # python-can cannot resume past damage: the rest of this file is lost, and said so
            bad.append(damage)
