"""The guard: what a link hears passes it before the engine (or a relay, or a sniffer) sees it.

C twin: vstig_hw/_cext/guard.c (JumpGuard: a guard of max_jump and learn only); held equal by tests/native (index:
vstig_hw/_vstig.pyi).

Virtual stigmergy trusts every message, so one robot with a corrupted counter, a
firmware bug or a flood could take a key over for the whole swarm, and a gateway
would spread the damage to every medium it joins. The guard refuses such traffic
at the gateway, without changing the protocol on the robots. It is sans-I/O: no
clock, no thread, no device; every call is handed the time.

Checks, in this order; a refused message is counted once, under the first reason
(`drop_<reason>` on the link), and never raised:

1. `untrusted`: the link has an allow-list (`trust`) and the sender is not on it
   (a medium that names nobody names no trusted sender), or the link has a
   deny-list that names the sender or the robot that wrote the entry: robots on
   a broadcast medium relay what a denied robot wrote under their own ids, and a
   medium that names nobody still carries the writer.
2. `source_rate`: the real source's token bucket is empty (`source_rate`
   messages per second, same burst). A sender id is a claim anyone can change per
   message; a source is what the gateway itself knows sent it: the link for serial
   and CAN; for zenoh, the session connected to ours that stamped the sample (a
   stamp naming no connected session is no source: such samples share the link's
   bucket; transports/zenoh.py).
3. `rate`: the sender's token bucket is empty (`rate` messages per second, a
   burst of one second's worth, at least one message). Senders are what the medium names (CAN node
   ids, zenoh gateway ids); where it names nobody the link is one sender.
4. `key`: the message would write a key outside the link's `keys`. Reading is
   allowed: an empty GET, or a GET older than our entry, passes and is answered.
5. `jump`: a PUT or GET newer than our entry for its key by more than
   `max_jump` timestamps, or one whose skipped timestamps (steps beyond the first)
   exceed the key's skip budget: `max_jump` a second, a burst of `max_jump`, so
   a climb of steps each within `max_jump` gains at most `max_jump` a second. A
   key we do not hold passes at any timestamp, unless `learn` seconds have passed
   since the guard's first message: then it is measured from timestamp 0 (a key
   new to the swarm starts at 1). The jump is quarantined: not stored, not
   relayed, and our entry stays as it was, so the robots that missed it see
   nothing, and a robot that stored it (one on the attacker's own medium) is
   refused each time it repeats it.

Two policies refuse nothing:

* `read_only` links: what they say reaches our table and listeners, but the
  entries they wrote never go out on another link (`confined_to`).
* Flapping: a key whose entry changes hands by conflict (same timestamp, another
  robot or another value) more than `flap` times within a second is reported once
  in `warnings`, naming the key and the two robots: usually two robots sharing an id.

Our entry for a key is the newest one the guard has let through (timestamp,
robot, value), kept here so the same guard serves an engine, a raw bridge and a
sniffer. Every table is bounded: at most one entry and skip budget per key
(32,768) and `MAX_SENDERS` token buckets per kind (senders, sources).
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ..counters import Counters
from ..timestamps import TS_NONE, is_newer, steps_ahead
from ..wire import GET_BIT, KEY_MAX, Message

__all__ = ["DEFAULT_MAX_JUMP", "MAX_SENDERS", "Guard", "IdSet", "LinkPolicy"]

# 255: every error in the timestamp's high byte (a flipped bit, a byte-swapped or
# half-written counter) moves it by 256 or more and is refused, while the gateway
# would have to miss 255 updates of one key in a row (25 s of a key written every
# 0.1 s control step) before an honest robot looked like a jump. An accepted
# forgery can silence honest writers of a key for at most 255 of their writes.
DEFAULT_MAX_JUMP = 255
MAX_SENDERS = 4096  # token buckets kept; beyond it, full (idle) buckets are forgotten
SMALL_SET = 4096  # an IdSet of at most this many ids is also kept as a frozenset


class IdSet:
    """A set of integers written as ranges, `1,2,5-9,0x10-0x1f`: membership by bisection, any size."""

    def __init__(self, ranges: Iterable[tuple[int, int]]) -> None:
        merged: list[tuple[int, int]] = []
        for lo, hi in sorted(ranges):
            if merged and lo <= merged[-1][1] + 1:
                merged[-1] = (merged[-1][0], max(merged[-1][1], hi))
            else:
                merged.append((lo, hi))
        self._lows = [lo for lo, _ in merged]
        self._highs = [hi for _, hi in merged]
        size = sum(hi - lo + 1 for lo, hi in merged)
        # A small set is a frozenset: one hash per message instead of a bisection.
        self._small = frozenset(n for lo, hi in merged for n in range(lo, hi + 1)) if size <= SMALL_SET else None

    @classmethod
    def parse(cls, text: str, limit: int, what: str = "ids") -> IdSet:
        """`1,2,5-9,0x10-0x1f`; ValueError naming `text` if a part is not a number or range in 0..limit."""
        ranges = []
        for part in text.split(","):
            lo_text, dash, hi_text = part.strip().partition("-")
            try:
                lo = int(lo_text, 0)
                hi = int(hi_text, 0) if dash else lo
            except ValueError:
                raise ValueError(f"bad {what} {text!r}: {part.strip()!r} is not a number or a range "
                                 "like 5-9 (e.g. 1,2,5-9,0x10-0x1f)") from None
            if not 0 <= lo <= hi <= limit:
                raise ValueError(f"bad {what} {text!r}: {part.strip()!r} is not a range within 0..{limit}")
            ranges.append((lo, hi))
        return cls(ranges)

    def __contains__(self, value: object) -> bool:
        if self._small is not None:
            return value in self._small and isinstance(value, int)
        if not isinstance(value, int):
            return False
        i = bisect.bisect_right(self._lows, value) - 1
        return i >= 0 and value <= self._highs[i]

    def __str__(self) -> str:
        return ",".join(str(lo) if lo == hi else f"{lo}-{hi}" for lo, hi in zip(self._lows, self._highs, strict=True))

    def __repr__(self) -> str:
        return f"IdSet({str(self)!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, IdSet) and (self._lows, self._highs) == (other._lows, other._highs)

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class LinkPolicy:
    """What one link may do. None means no restriction."""

    trust: IdSet | None = None  # only these senders
    deny: IdSet | None = None  # never these senders
    keys: IdSet | None = None  # the keys it may write
    read_only: bool = False  # heard, stored, never relayed to other links


_OPEN = LinkPolicy()


class Guard:
    """The policies for every link (`links`, by link name) and the state they need; see the module's docstring.

    `max_jump` (None: off), `rate` in messages per second per sender, `source_rate` per real
    source, `learn` in seconds and `flap` in conflicts per second (each None: off) apply to every link.
    """

    confines: bool  # a link is read-only (declared: the compiled Seat reads it too)

    def __init__(
        self,
        *,
        max_jump: int | None = DEFAULT_MAX_JUMP,
        rate: float | None = None,
        source_rate: float | None = None,
        learn: float | None = None,
        flap: float | None = None,
        links: Mapping[str, LinkPolicy] | None = None,
    ) -> None:
        if max_jump is not None and not 1 <= max_jump <= 0x7FFF:
            raise ValueError(f"max_jump must be 1..32767 timestamps (or None: off), got {max_jump!r}")
        for name, limit in (("rate", rate), ("source_rate", source_rate)):
            if limit is not None and not limit > 0:
                raise ValueError(f"{name} must be a positive number of messages per second (or None: off), "
                                 f"got {limit!r}")
        if learn is not None and not learn >= 0:
            raise ValueError(f"learn must be a number of seconds >= 0 (or None: off), got {learn!r}")
        if flap is not None and not flap > 0:
            raise ValueError(f"flap must be a positive number of conflicts per second (or None: off), got {flap!r}")
        self.max_jump = max_jump
        self.rate = rate
        self.source_rate = source_rate
        self.learn = learn
        self._started: float | None = None  # when the first message was checked (the learning starts)
        self.flap = flap
        self.policies = dict(links or {})
        self.warnings: list[str] = []  # for the caller to print (and clear)
        self._view: dict[int, tuple[int, int, int]] = {}  # key -> (timestamp, robot, value) let through
        self._buckets: dict[tuple[str, int | None], list[float]] = {}  # (link, sender) -> [tokens, last time]
        self._source_buckets: dict[tuple[str, str | None], list[float]] = {}  # (link, source) -> same
        self._skips: dict[int, list[float]] = {}  # key -> [skip budget left, last time]
        self._confined: dict[int, tuple[int, int, str]] = {}  # key -> (timestamp, robot, read-only link)
        self._flaps: dict[int, list[float]] = {}  # key -> [window start, conflicts in it, timestamp of the last]
        self._warned: set[int] = set()
        self.confines = any(p.read_only for p in self.policies.values())

    # -- the gateway's calls -------------------------------------------------------
    def filter(self, link: str, sender: int | None, messages: list[Message], now: float,
               counters: Counters, source: str | None = None) -> list[Message]:
        """The messages that pass; each refused one is counted in `counters` as `drop_<reason>`."""
        kept = []
        for msg in messages:
            reason = self.check(link, sender, msg, now, source)
            if reason is None:
                kept.append(msg)
            else:
                counters[reason] += 1
        return kept

    def check(self, link: str, sender: int | None, msg: Message, now: float,
              source: str | None = None) -> str | None:
        """None if `msg` (heard on `link` from `sender`, sent by `source`, at `now` seconds) passes, else its
        drop counter name. `source` None: the link is the source."""
        policy = self.policies.get(link, _OPEN)
        head, value, ts, robot = msg
        if self._started is None:
            self._started = now
        if (policy.trust is not None and sender not in policy.trust) or (
                policy.deny is not None and (sender in policy.deny or robot in policy.deny)):
            return "drop_untrusted"
        if self.source_rate is not None and not _take_token(self._source_buckets, (link, source),
                                                            self.source_rate, now):
            return "drop_source_rate"
        if self.rate is not None and not _take_token(self._buckets, (link, sender), self.rate, now):
            return "drop_rate"
        key = head & KEY_MAX
        view = self._view.get(key)
        if policy.keys is not None and key not in policy.keys and _writes(head, ts, robot, value, view):
            return "drop_key"
        if ts == TS_NONE:
            return None  # an empty GET: says nothing about the entry
        if self.max_jump is not None and self._jumps(key, ts, view, now):
            return "drop_jump"
        self._let_through(link, policy, key, ts, robot, value, view, now)
        return None

    def read_only(self, link: str) -> bool:
        """Whether nothing `link` hears may be relayed to another link."""
        return self.policies.get(link, _OPEN).read_only

    def confined_to(self, msg: Message) -> str | None:
        """The read-only link whose robot wrote the entry `msg` carries (it goes out only there), else None."""
        origin = self._confined.get(msg[0] & KEY_MAX)
        return origin[2] if origin is not None and origin[0] == msg[2] and origin[1] == msg[3] else None

    # -- the policies ----------------------------------------------------------------
    def _jumps(self, key: int, ts: int, view: tuple[int, int, int] | None, now: float) -> bool:
        """Whether `ts` is a jump for `key`; if not, and it moves the key, its skipped steps are spent."""
        max_jump = self.max_jump
        assert max_jump is not None
        if view is not None:
            held = view[0]
        elif self.learn is not None and self._started is not None and now - self._started >= self.learn:
            held = TS_NONE  # learnt: a key nobody mentioned so far is new, and starts at 1
        else:
            return False
        if not is_newer(ts, held):
            return False
        steps = ts if held == TS_NONE else steps_ahead(ts, held)
        if steps > max_jump:
            return True
        budget = self._skips.get(key)
        if budget is None:
            budget = self._skips[key] = [float(max_jump), now]
        left = min(float(max_jump), budget[0] + max(0.0, now - budget[1]) * max_jump)  # refills max_jump a second
        budget[1] = now
        if steps - 1 > left:
            budget[0] = left
            return True
        budget[0] = left - (steps - 1)
        return False

    def _let_through(self, link: str, policy: LinkPolicy, key: int, ts: int, robot: int, value: int,
                     view: tuple[int, int, int] | None, now: float) -> None:
        if view is None or is_newer(ts, view[0]):
            self._view[key] = (ts, robot, value)
        elif ts == view[0] and (robot, value) != view[1:]:
            self._count_flap(key, ts, view[1], robot, now)
        else:
            return  # older than our entry, or the same: it writes nothing
        if policy.read_only:
            self._confined[key] = (ts, robot, link)

    def _count_flap(self, key: int, ts: int, robot: int, other: int, now: float) -> None:
        """Count conflicts at distinct timestamps: the same conflict heard again from other robots is not news."""
        if self.flap is None or key in self._warned:
            return
        window = self._flaps.setdefault(key, [now, 0.0, TS_NONE])
        if window[2] == ts:
            return
        if not 0.0 <= now - window[0] < 1.0:  # a new second (or the clock stepped back)
            window[0], window[1] = now, 0.0
        window[1] += 1
        window[2] = ts
        if window[1] > self.flap:
            self._warned.add(key)
            del self._flaps[key]
            pair = f"robots {min(robot, other)} and {max(robot, other)}" if robot != other \
                else f"robot {robot} with two values (two robots sharing id {robot}?)"
            self.warnings.append(f"warning: key {key} changes hands by conflict more than {self.flap:g} times "
                                 f"a second, between {pair}")


def _take_token(buckets: dict[tuple[str, Any], list[float]], who: tuple[str, Any], rate: float, now: float) -> bool:
    """Take a token from `who`'s bucket (`rate` a second, a burst of one second's worth, at least one)."""
    burst = max(rate, 1.0)
    bucket = buckets.get(who)
    if bucket is None:
        if len(buckets) >= MAX_SENDERS:
            _forget_full_buckets(buckets, rate, burst, now)
        bucket = buckets[who] = [burst, now]
    tokens = min(burst, bucket[0] + max(0.0, now - bucket[1]) * rate)  # a clock stepping back adds none
    bucket[1] = now
    if tokens < 1.0:
        bucket[0] = tokens
        return False
    bucket[0] = tokens - 1.0
    return True


def _forget_full_buckets(buckets: dict[tuple[str, Any], list[float]], rate: float, burst: float,
                         now: float) -> None:
    """Drop the buckets that have refilled: a new bucket starts full, so nothing changes for them."""
    for who, (tokens, last) in list(buckets.items()):
        if tokens + max(0.0, now - last) * rate >= burst:
            del buckets[who]


def _writes(head: int, ts: int, robot: int, value: int, view: tuple[int, int, int] | None) -> bool:
    """Whether a message could change our entry: every PUT; a GET unless it is empty or older than our entry."""
    if not head & GET_BIT:
        return True
    if ts == TS_NONE:
        return False
    return view is None or not (is_newer(view[0], ts) or (ts, robot, value) == view)
