"""16-bit Lamport timestamps compared by serial-number arithmetic (RFC 1982).

Buzz compares timestamps with a plain `<`, so after 65,535 updates a key wraps
to a small number that every peer ignores forever. Comparing the difference
modulo 2**16 keeps a key alive across the wrap, as long as two views of it are
less than 32,768 updates apart. Timestamp 0 is reserved for "no entry": it is
older than everything and is skipped when a counter wraps.
"""

from __future__ import annotations

TS_NONE = 0
TS_MAX = 0xFFFF
_HALF = 0x8000


def is_newer(a: int, b: int) -> bool:
    """True when timestamp `a` is strictly newer than `b`.

    The exact half-way distance (32,768) is undefined in RFC 1982; we break it
    by plain magnitude so the relation stays antisymmetric and every robot
    resolves it the same way.
    """
    if b == TS_NONE:
        return a != TS_NONE
    if a == TS_NONE:
        return False
    distance = (a - b) & TS_MAX
    return 0 < distance < _HALF or (distance == _HALF and a > b)


def next_timestamp(ts: int) -> int:
    """The timestamp after `ts`, skipping the reserved 0 on wrap (65535 -> 1)."""
    return ts + 1 if ts < TS_MAX else 1


def steps_ahead(newer: int, older: int) -> int:
    """How many `next_timestamp` steps lead from `older` to `newer` (for `newer` newer than a nonzero `older`).

    The modular distance, less one when the path wrapped past the skipped 0.
    """
    distance = (newer - older) & TS_MAX
    return distance - 1 if newer < older else distance
