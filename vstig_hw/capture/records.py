"""What a capture holds (timestamped link units), the one error for a bad file, and who reads each format.

As python-can's `MESSAGE_READERS` maps a log's suffix to its reader, `READERS` maps a capture format to
(module in this package, its reader function) and `WRITERS` a medium to (module, its writer class); a
module is imported only when a file of its format is read or written. `sniff` tells a file's format
with one open: our line captures by their header (any name), every other format by its extension.
Adding a format is one reader module plus one line here.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import IO, Any, TypeVar, cast

__all__ = ["APPENDABLE", "CAN_EXTENSIONS", "CAN_FRAMING", "LINE_CAPTURE_HEADERS", "MCAP_EXTENSION",
           "MESSAGE_FRAMING", "NAMELESS_EXTENSIONS", "READABLE_EXTENSIONS", "READERS", "STRICT", "WRITERS",
           "CaptureError", "Damage", "Record", "capture_suffix", "cut_short", "file_position", "line_capture_at",
           "line_capture_format", "link_names_lost", "parse_lines", "read_capture", "reader_for", "sniff",
           "sniff_suffix", "writer_class"]

T = TypeVar("T")

CAN_FRAMING = "can"  # the framing name CAN records carry (CAN logs have no framing field)
MESSAGE_FRAMING = "message"  # records whose unit is a decoded (Message, sender): MCAP captures hold those


class CaptureError(ValueError):
    """A file that cannot be read as a capture; the message starts `file:line:`."""

    def __init__(self, path: str, line: int | None, problem: str) -> None:
        self.path, self.line, self.problem = path, line, problem
        where = f"{path}:{line}" if line is not None else path
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True, slots=True)
class Record:
    """One unit read from (or written to) a link: a `can.Message` or a chunk of UART bytes."""

    t: float
    link: str
    framing: str
    unit: Any
    direction: str = "rx"


class Damage:
    """What reading does with damaged input (a malformed line, a file cut short): raise it, or with `skip`
    count it and go on (`--skip-bad`), keeping the first `keep` to name. One travels through every reader.

    `STRICT`, the readers' default, raises at the first damage and so never changes.
    """

    __slots__ = ("count", "first", "keep", "skip")

    def __init__(self, skip: bool = False, keep: int = 100) -> None:
        self.skip, self.keep = skip, keep
        self.count = 0  # every damage skipped
        self.first: list[CaptureError] = []  # the first `keep` of them, in the order met

    def fresh(self) -> Damage:
        """The same policy, nothing counted yet (for each file, or each pass, reported apart)."""
        return Damage(self.skip, self.keep)

    def record(self, error: CaptureError) -> None:
        """Raise `error`, or with `skip` count it (and keep it, among the first few) so reading goes on."""
        if not self.skip:
            raise error from None
        self.count += 1
        if len(self.first) < self.keep:
            self.first.append(error)


STRICT = Damage()


def cut_short(path: str, kept: int, unit: str, lost: str, damage: Damage) -> None:
    """Report a capture that ends mid-record (a recorder killed, a disk full) after its `kept` complete `unit`s.

    Every reader says it the same one way, after handing on all it could read, so decode, analyze and
    replay show one line naming what was kept and what was lost; a skipping `damage` counts it.
    """
    damage.record(CaptureError(path, None, f"cut short (its recorder did not close it): read all {kept} {unit} "
                               f"before the cut; {lost}"))


def parse_lines(path: str, lines: Iterable[str], parse: Callable[[str, int, str], T | None], damage: Damage,
                first_line: int = 1) -> Iterator[T]:
    """Parse numbered lines (from `first_line`); a bad line goes to `damage` (raised, or counted and skipped)."""
    for number, line in enumerate(lines, first_line):
        try:
            item = parse(path, number, line)
        except CaptureError as error:
            damage.record(error)
            continue
        if item is not None:
            yield item


CAN_EXTENSIONS = (".log", ".asc", ".blf", ".csv", ".pcap", ".trc", ".log.gz", ".asc.gz")
MCAP_EXTENSION = ".mcap"  # rosbag2 MCAP (capture.rosbag): decoded messages of any links
READ_ONLY_EXTENSIONS = (".pcapng",)  # formats we read but do not write (Wireshark's default)
READABLE_EXTENSIONS = (*CAN_EXTENSIONS, *READ_ONLY_EXTENSIONS, MCAP_EXTENSION)
APPENDABLE = (".log", ".blf", ".csv", ".log.gz")  # the CAN formats python-can's writers can add to
NAMELESS_EXTENSIONS = (".csv", ".pcap", ".trc")  # CAN formats with no channel or name: one link, unnamed
# Our line captures, found by their first line whatever the file is called: header stem -> format.
LINE_CAPTURE_HEADERS = {"# vstig serial capture": "serial", "# vstig zenoh capture": "zenoh"}
_CAN_LOG = ("canlog", "read_can_log")  # python-can's readers (and ours for pcap, registered with python-can)
READERS: dict[str, tuple[str, str]] = {
    "serial": ("serial_log", "read_serial_capture"),
    "zenoh": ("zenoh_log", "read_zenoh_capture"),
    ".log": ("candump", "read_candump"),
    ".log.gz": ("candump", "read_candump"),
    MCAP_EXTENSION: ("rosbag", "read_mcap"),
    **{suffix: _CAN_LOG for suffix in READABLE_EXTENSIONS if suffix not in (".log", ".log.gz", MCAP_EXTENSION)},
}
WRITERS: dict[str, tuple[str, str]] = {  # by medium; a CAN writer picks python-can's format by extension
    "can": ("canlog", "CanCaptureWriter"),
    "serial": ("serial_log", "SerialCaptureWriter"),
    "zenoh": ("zenoh_log", "ZenohCaptureWriter"),
    "mcap": ("rosbag", "McapCaptureWriter"),
}
_HEAD_BYTES = max(map(len, LINE_CAPTURE_HEADERS))
_PCAP_MAGICS = tuple(m.to_bytes(4, order) for m in (0xA1B2C3D4, 0xA1B23C4D) for order in ("big", "little"))

# Every reader: (path, damage, opened) -> records in file order; see `read_capture`.
Reader = Callable[[str, Damage, Callable[[IO[Any]], None] | None], Iterator[Record]]


def capture_suffix(path: str) -> str:
    """The extension that tells a capture's format: `.log`, `.log.gz`... (lower case)."""
    suffixes = Path(path).suffixes
    return "".join(suffixes[-2:]).lower() if suffixes[-1:] == [".gz"] else "".join(suffixes[-1:]).lower()


def link_names_lost(path: str) -> bool:
    """Whether a CAN capture at `path` names no link (CSV, pcap, TRC): it can hold only one, unnamed."""
    return capture_suffix(path) in NAMELESS_EXTENSIONS


def line_capture_format(head: bytes) -> str | None:
    """`serial` or `zenoh` for a file starting with our line capture's header (any version), else None."""
    for stem, fmt in LINE_CAPTURE_HEADERS.items():
        if head.startswith(stem.encode()):
            return fmt
    return None


def line_capture_at(path: str) -> str | None:
    """`serial` or `zenoh` for a file that starts with our line capture's header (any version, any name)."""
    with open(path, "rb") as file:
        return line_capture_format(file.read(_HEAD_BYTES))


def sniff(path: str) -> str:
    """The format of the capture at `path`, a key of `READERS`, from one open: its header, else its extension."""
    if not os.path.isfile(path):
        raise CaptureError(path, None, "no such file")
    found = line_capture_at(path)
    if found is not None:
        return found
    suffix = capture_suffix(path)
    if suffix not in READERS:
        raise CaptureError(path, None, f"unknown capture type {suffix or '(no extension)'!r}: expected a "
                           f"serial capture or one of {', '.join(READABLE_EXTENSIONS)}")
    return suffix


def sniff_suffix(head: bytes) -> str | None:
    """The capture type a file's first bytes show, as its extension (for a stream with no name to go by)."""
    if line_capture_format(head) is not None:  # found by header, any name
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


def _member(module: str, name: str) -> Any:
    return getattr(import_module(f".{module}", __package__), name)


def read_capture(path: str, damage: Damage = STRICT, opened: Callable[[IO[Any]], None] | None = None,
                 fmt: str | None = None) -> Iterator[Record]:
    """Every record of a capture, by the reader of its format (`fmt`, or what `sniff` finds); damage goes to
    `damage` (by default raised).

    `opened` is handed the file being read once it is open, so a caller can tell how far reading got
    (`file_position`); the MCAP reader does not show its file.
    """
    yield from reader_for(fmt or sniff(path))(path, damage, opened)


def reader_for(fmt: str) -> Reader:
    """The reader of a format (a key of `READERS`), its module imported now."""
    return cast(Reader, _member(*READERS[fmt]))


def writer_class(medium: str) -> Callable[..., Any]:
    """The `CaptureWriter` class for a medium (can, serial, zenoh, mcap), its module imported now."""
    return cast(Callable[..., Any], _member(*WRITERS[medium]))


def file_position(file: IO[Any]) -> int | None:
    """How many bytes of the file on disk were read so far (compressed bytes for .gz); None for a pipe."""
    try:
        return os.lseek(file.fileno(), 0, os.SEEK_CUR)
    except (OSError, ValueError, AttributeError):
        return None
