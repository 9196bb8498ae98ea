"""The time column of decode's text lines, in candump's four styles (`candump -t a|A|d|z`).

    a  (1700000000.250000)           seconds since the epoch, as the capture holds them
    A  (2023-11-14 22:13:20.250000)  local date and time
    d  (000.000250)                  seconds since the line before (0 for the first)
    z  (012.500000)                  seconds since the first line

One clock runs over every file decode is given, so z and d go on across them as
across one long capture.
"""

from __future__ import annotations

import time

__all__ = ["TIME_STYLES", "TimeColumn"]

TIME_STYLES = ("a", "A", "d", "z")


class TimeColumn:
    def __init__(self, style: str = "a") -> None:
        if style not in TIME_STYLES:
            raise ValueError(f"time style must be one of {', '.join(TIME_STYLES)}, got {style!r}")
        self.style = style
        self._first: float | None = None
        self._last: float | None = None

    def __call__(self, t: float) -> str:
        first = self._first = t if self._first is None else self._first
        last, self._last = self._last, t
        if self.style == "a":
            return f"({t:.6f})"
        if self.style == "A":
            seconds, micros = divmod(round(t * 1e6), 1_000_000)
            return f"({time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(seconds))}.{micros:06d})"
        since = t - (first if self.style == "z" or last is None else last)
        return f"({since:010.6f})"  # candump's %03lu.%06lu: at least three digits of seconds
