"""Link names in ASC and BLF captures, whose frames carry only a channel number.

The writer numbers the links 1, 2... in the order they first appear and notes each
number's name in the file just before the first frame on it: an ASC comment line
(`// vstig link 2 can1`, which CANoe, python-can and asc2log pass over) or a BLF
APP_TEXT object (a comment, which BLF readers skip). The ASC note also keeps the
first frame's exact time (`// vstig start 1700000000.123456`): ASC dates its
trigger block only to the millisecond. Our readers turn the numbers back into
names; a file from another tool keeps its channel numbers.
"""

from __future__ import annotations

import contextlib
import gzip
import struct
from collections.abc import Iterator
from typing import IO, Any

import can

__all__ = ["BLF_APP_TEXT", "AscNotes", "ChannelNumbers", "NamedBlfReader", "asc_note", "asc_start", "blf_note",
           "read_asc_notes"]

BLF_APP_TEXT = 65  # Vector's object type for application text (comments, metadata)
_APP_TEXT_HEAD = struct.Struct("<IIII")  # source (0: measurement comment), reserved, text length, reserved
_OBJECT_HEAD = struct.Struct("<4sHHII")  # LOBJ, header size, header version, object size, object type
_NOTE = "vstig link "
_START = "vstig start "


class ChannelNumbers:
    """Each link's channel number (1, 2... by first appearance), as python-can's writers take it (0-based)."""

    def __init__(self) -> None:
        self._numbers: dict[str, int] = {}

    def number(self, link: str) -> tuple[int, bool]:
        """(the 1-based number for `link`, whether it is new and so needs its note)."""
        known = self._numbers.get(link)
        if known is not None:
            return known, False
        number = self._numbers[link] = len(self._numbers) + 1
        return number, True


def asc_note(number: int, link: str) -> str:
    return f"// {_NOTE}{number} {link}\n"


def asc_start(t: float) -> str:
    return f"// {_START}{t:.6f}\n"


def blf_note(number: int, link: str) -> bytes:
    """An APP_TEXT object's data naming channel `number`."""
    text = f"{_NOTE}{number} {link}".encode()
    return _APP_TEXT_HEAD.pack(0, 0, len(text), 0) + text


def _parse_note(text: str, names: dict[int, str]) -> None:
    number, _, link = text[len(_NOTE):].partition(" ")
    if number.isascii() and number.isdigit() and link:
        names[int(number) - 1] = link  # python-can's readers number channels from 0


class AscNotes:
    """What our notes in an ASC file say: channel names (by python-can's 0-based channel) and the exact start."""

    def __init__(self) -> None:
        self.names: dict[int, str] = {}
        self.start: float | None = None


def read_asc_notes(path: str) -> AscNotes:
    notes = AscNotes()
    opener: Any = gzip.open if path.lower().endswith(".gz") else open
    file: IO[str]
    # A killed recorder's .asc.gz ends without its gzip trailer: the notes before the cut still count,
    # and the frame reader reports the cut.
    with opener(path, "rt", encoding="utf-8", errors="replace") as file, contextlib.suppress(EOFError):
        for line in file:
            if not line.startswith("// vstig "):
                continue
            text = line[3:].strip()
            if text.startswith(_NOTE):
                _parse_note(text, notes.names)
            elif text.startswith(_START) and notes.start is None:
                with contextlib.suppress(ValueError):  # a damaged note: the trigger block's time will do
                    notes.start = float(text[len(_START):])
    return notes


class NamedBlfReader(can.BLFReader):
    """python-can's BLF reader that also reads our APP_TEXT notes into `names`, before the frames they name."""

    def __init__(self, file: Any, **kwargs: Any) -> None:
        super().__init__(file, **kwargs)
        self.names: dict[int, str] = {}

    def _parse_data(self, data: bytes) -> Iterator[can.Message]:
        # The whole objects in `data` (python-can hands over a container plus the part-object left before it);
        # objects are padded to 4 bytes, so the next one starts within a few bytes of where the last ended.
        pos = 0
        while (pos := data.find(b"LOBJ", pos, pos + 8)) >= 0 and pos + _OBJECT_HEAD.size <= len(data):
            _, header_size, _, size, kind = _OBJECT_HEAD.unpack_from(data, pos)
            if size < _OBJECT_HEAD.size or pos + size > len(data):
                break
            if kind == BLF_APP_TEXT and size >= header_size + _APP_TEXT_HEAD.size:
                _, _, length, _ = _APP_TEXT_HEAD.unpack_from(data, pos + header_size)
                start = pos + header_size + _APP_TEXT_HEAD.size
                text = data[start:start + length].decode("utf-8", "replace")
                if text.startswith(_NOTE):
                    _parse_note(text, self.names)
            pos += size
        yield from super()._parse_data(data)
