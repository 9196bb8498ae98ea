"""Decision notes in captures: what a recording gateway decided that nothing on the wire shows.

    # vstig decision (1700000000.250000) ttyUSB1 tx_overflow 12
    # vstig decision (1700000000.250000) can0 drop_jump 1 sender=7 key=3 ts=40001 robot=7
    # vstig decision (1700000000.300000) engine conflict 1

Comment lines, as the clock notes are (clock_notes), written through the same `RotatingCapture.note`. Each
is one counter's growth over one control tick on one link (`engine`: the engine's own outcomes), so a tick
writes at most one line per counter and link however busy the link; a guard's refusal also names the message
it refused, for at most `REFUSALS_PER_TICK` refusals a tick (the counter line still counts them all). One
note is a state, not a growth: `queued N`, the messages waiting for a link (its outlet and writer), noted
when it changes (a device that takes nothing: N stays up).
`vstig why` reads them beside the records (docs/how-to/why.md).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

__all__ = ["DECISION_PREFIX", "ENGINE_NOTES", "QUEUED", "REFUSALS_PER_TICK", "Decision", "counted_note",
           "decisions_in", "noted_counter", "parse_decision", "refusal_note"]

DECISION_PREFIX = "# vstig decision "
QUEUED = "queued"  # the messages waiting for a link, noted when the number changes
ENGINE_NOTES = "engine"  # the link name of the engine's outcome notes (a link may not take it: counters.ENGINE_STATS)
REFUSALS_PER_TICK = 32  # refusals named message by message per tick; beyond, the counter's note alone
_LINE = re.compile(r"# vstig decision \((\d{1,12}\.\d{1,9})\) (\S{1,200}) ([a-z_]{1,40}) (\d{1,12})"
                   r"(?: sender=(-|\d{1,10}) key=(\d{1,10}) ts=(\d{1,10}) robot=(\d{1,10}))?\s*\Z")


def noted_counter(name: str) -> bool:
    """Whether a link counter is a gateway decision worth a note: a drop (the guard's refusals, the fair share's
    drop_intake...) or an overflowing outlet (tx_overflow)."""
    return name.startswith("drop_") or name == "tx_overflow"


@dataclass(frozen=True, slots=True)
class Decision:
    t: float
    link: str
    reason: str  # the counter: drop_jump, drop_intake, tx_overflow, conflict...
    count: int
    sender: int | None = None  # a refusal's message (None: a counter's growth, or a medium that names no sender)
    key: int | None = None
    ts: int | None = None
    robot: int | None = None

    @property
    def names_a_message(self) -> bool:
        return self.key is not None

    @property
    def entry(self) -> tuple[int, int, int] | None:
        """A refusal's (key, timestamp, robot); None for a counter's growth."""
        if self.key is None or self.ts is None or self.robot is None:
            return None
        return self.key, self.ts, self.robot


def counted_note(t: float, link: str, reason: str, count: int) -> str:
    return f"vstig decision ({t:.6f}) {link} {reason} {count}"


def refusal_note(t: float, link: str, reason: str, sender: int | None, key: int, ts: int, robot: int) -> str:
    who = "-" if sender is None else str(sender)
    return f"vstig decision ({t:.6f}) {link} {reason} 1 sender={who} key={key} ts={ts} robot={robot}"


def parse_decision(line: str) -> Decision | None:
    """The decision a comment line notes, or None (another note, or a line that does not parse)."""
    found = _LINE.match(line)
    if found is None:
        return None
    t, link, reason, count, sender, key, ts, robot = found.groups()
    if key is None:
        return Decision(float(t), link, reason, int(count))
    return Decision(float(t), link, reason, int(count), None if sender == "-" else int(sender), int(key), int(ts),
                    int(robot))


def decisions_in(lines: Iterable[str]) -> Iterator[Decision]:
    for line in lines:
        if line.startswith(DECISION_PREFIX) and (decision := parse_decision(line)) is not None:
            yield decision
