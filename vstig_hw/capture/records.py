"""What a capture holds: timestamped link units, and the one error for a bad file."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

__all__ = ["CAN_FRAMING", "MESSAGE_FRAMING", "CaptureError", "Record", "parse_lines"]

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


def parse_lines(path: str, lines: Iterable[str], parse: Callable[[str, int, str], T | None], skip_bad: bool,
                bad: list[CaptureError] | None, first_line: int = 1) -> Iterator[T]:
    """Parse numbered lines (from `first_line`); a bad line raises, or with `skip_bad` is collected in `bad`."""
    for number, line in enumerate(lines, first_line):
        try:
            item = parse(path, number, line)
        except CaptureError as error:
            if not skip_bad:
                raise
            if bad is not None:
                bad.append(error)
            continue
        if item is not None:
            yield item
