"""What a capture holds: timestamped link units, and the one error for a bad file."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["CAN_FRAMING", "CaptureError", "Record"]

CAN_FRAMING = "can"  # the framing name CAN records carry (CAN logs have no framing field)


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
