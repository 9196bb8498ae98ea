"""Named counters for everything dropped or moved: CRC failures, stale fragments...

Every framing, transport and link owns one; `sniff` and `bridge` show them.
"""

from __future__ import annotations

from collections import Counter

# A gateway's stats() entry of the engine's outcome counts; a link may not take this name.
ENGINE_STATS = "engine"


class Counters(Counter[str]):
    """A Counter of event names ("crc", "bad_length", "rx", ...) with a terse summary."""

    def summary(self) -> str:
        return " ".join(f"{name}={count}" for name, count in sorted(self.items()) if count) or "-"
