"""What a capture holds: timestamped link units, and the one error for a bad file."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

__all__ = ["CAN_FRAMING", "MESSAGE_FRAMING", "CaptureError", "Record", "cut_short", "parse_lines", "skip_or_raise"]

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


def skip_or_raise(error: CaptureError, skip_bad: bool, bad: list[CaptureError] | None) -> None:
    """Raise `error`, or with `skip_bad` collect it in `bad` so reading goes on."""
    if not skip_bad:
        raise error
    if bad is not None:
        bad.append(error)


def cut_short(path: str, kept: int, unit: str, lost: str, skip_bad: bool, bad: list[CaptureError] | None) -> None:
    """Report a capture that ends mid-record (a recorder killed, a disk full) after its `kept` complete `unit`s.

    Every reader says it the same one way, after handing on all it could read, so decode, analyze and
    replay show one line naming what was kept and what was lost; `skip_bad` makes it a skipped line.
    """
    skip_or_raise(CaptureError(path, None, f"cut short (its recorder did not close it): read all {kept} {unit} "
                               f"before the cut; {lost}"), skip_bad, bad)


def parse_lines(path: str, lines: Iterable[str], parse: Callable[[str, int, str], T | None], skip_bad: bool,
                bad: list[CaptureError] | None, first_line: int = 1) -> Iterator[T]:
    """Parse numbered lines (from `first_line`); a bad line raises, or with `skip_bad` is collected in `bad`."""
    for number, line in enumerate(lines, first_line):
        try:
            item = parse(path, number, line)
        except CaptureError as error:
            skip_or_raise(error, skip_bad, bad)
            continue
        if item is not None:
            yield item
