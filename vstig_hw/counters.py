"""Named counters for everything dropped or moved: CRC failures, stale fragments...

Every framing, transport and link owns one; `sniff` and `bridge` show them. C twin: vstig_hw/_cext/pending.c.

The compiled data path adds its hottest counts (in, out, tx, tx_bytes, rx, rx_bytes, not_echoed: up to nine a
relayed message) to C integers beside the dict, `Counters.pending`, rather than into the dict (two lookups and an int
object a count): every read of a Counters folds them in first, so a reader never sees a count missing.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any, Protocol

# A gateway's stats() entry of the engine's outcome counts; a link may not take this name.
ENGINE_STATS = "engine"


class PendingCounts(Protocol):
    """What the compiled path holds for a Counters (`vstig_hw._vstig.PendingCounts`)."""

    def fold(self, counters: Counters, /) -> None: ...  # add what is pending into counters, and clear it
    def forget(self) -> None: ...  # counters lost names: each one's next count goes into the dict again


class Counters(Counter[str]):
    """A Counter of event names ("crc", "bad_length", "rx", ...) with a terse summary."""

    # The compiled path's hot counts of this Counters (vstig_hw/_cext/pending.c), once it keeps them: None, all in
    # the dict.
    pending: PendingCounts | None = None

    def summary(self) -> str:
        return " ".join(f"{name}={count}" for name, count in sorted(self.items()) if count) or "-"

    def keep_pending(self, pending: PendingCounts) -> None:
        """Let the compiled path keep this Counters' hot counts in `pending`: from now on each read folds them in.
        Only such a Counters pays for the folding (a class of its own): Python's own counting elsewhere does not."""
        self.pending = pending
        self.__class__ = SettlingCounters


def _settled_first(read: Callable[..., Any], forgets: bool) -> Callable[..., Any]:
    def settled(self: Counters, *args: Any, **kwargs: Any) -> Any:
        pending = self.pending
        if pending is not None:
            pending.fold(self)
        result = read(self, *args, **kwargs)
        if forgets and pending is not None:
            pending.forget()
        return result

    settled.__name__ = settled.__qualname__ = read.__name__
    settled.__doc__ = read.__doc__
    return settled


class SettlingCounters(Counters):
    """A Counters whose hot counts the compiled path keeps in C (`keep_pending`): every read folds them in first.

    Counter's own methods (most_common, total, repr, +, |, and dict(counters), whose fast path an overridden
    __iter__ turns off) read through the ones below. A write does not fold: `counters[name] += 1` is a read, then a
    set of what it read plus one, and counts the C adds in between stay pending rather than being overwritten. The
    ones that remove names also make each name's next count go into the dict, so a dict with counts pending is
    never empty (json's encoder writes an empty dict without asking it). A copy holds nothing pending; a
    pickled one comes back a plain Counters.
    """

    __slots__ = ()

    def __reduce__(self) -> tuple[type[Counters], tuple[dict[str, int]]]:
        return Counters, (dict(self),)


for _name in ("__getitem__", "get", "__contains__", "__iter__", "__len__", "keys", "values", "items", "setdefault",
              "__eq__", "__ne__"):
    setattr(SettlingCounters, _name, _settled_first(getattr(Counter, _name), forgets=False))
for _name in ("pop", "popitem", "__delitem__", "clear"):
    setattr(SettlingCounters, _name, _settled_first(getattr(Counter, _name), forgets=True))
