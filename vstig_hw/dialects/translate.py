"""Translators between each dialect's vstig messages and our Message, for one deployment.

Each translator is pure and counts what it cannot carry in `drops`:
`drop_unmapped` (a name, stigmergy or value the deployment does not map exactly) and
the guards below. Timestamps, writers and the PUT/GET distinction cross unchanged
where the widths allow.

Buzz: a QUERY for a key its sender does not hold (nil, timestamp 0) is our empty
GET (value 0, timestamp 0) and back. Other nils (Buzz's put(nil) tombstones) have
no equivalent in our format and are unmapped. A version whose timestamp wrapped
past 65535 is not sent to Buzz robots, which would ignore it forever (`buzz_wrap`).

BittyBuzz guards (its firmware's known defects, DIALECTS D.5):
- only PUTs go to the Kilobots: a Kilobot stores any vstig message for a key it
  does not hold, so a QUERY would plant its value (or nil) there;
- at most `capacity` keys (BBZVSTIG_CAP): an incoming message for one more key is
  written past the end of the Kilobot's store (`guard_capacity`);
- a Kilobot's repeat of a version we know (the echo storm of pre-2021 firmware, or
  a query reply carrying the replier's id) is not news (`bbz_repeat`);
- timestamps go through the per-key Lamport anchors of `lamport`.

A version lost on its way to the Kilobots is repaired when a Kilobot shows it
lacks it (a query for a key it does not hold, an older lamport, a losing
conflict): that becomes our empty GET, our engine answers with its entry, and
that entry goes back to the Kilobots at the anchor's lamport (one step past the
older one). Our side's next write goes out one step ahead anyway.
"""

from __future__ import annotations

from ..counters import Counters
from ..timestamps import is_newer
from ..wire import Message, Op
from .bittybuzz import BbzOp, BbzType, BbzVstig
from .buzz import BuzzOp, BuzzVstig
from .lamport import BBZ_LAMPORT_THRESHOLD, LamportBridge, Verdict
from .mapping import Deployment

__all__ = ["BittyBuzzTranslator", "BuzzTranslator"]

UNMAPPED = "unmapped"  # shown as drop_unmapped in a link's counters


class BuzzTranslator:
    def __init__(self, deployment: Deployment, drops: Counters | None = None) -> None:
        self.deployment = deployment
        self.drops = drops if drops is not None else Counters()
        self._highest: dict[int, int] = {}  # per our key, the highest timestamp the Buzz side has shown

    def _wrapped(self, key: int, timestamp: int) -> bool:
        """Buzz compares timestamps with a plain `<`: a version that is newer only because our counter
        wrapped past 65535 would be ignored by every Buzz robot, forever (`buzz_wrap`)."""
        highest = self._highest.get(key)
        return highest is not None and timestamp < highest and is_newer(timestamp, highest)

    def to_ours(self, msg: BuzzVstig) -> Message | None:
        entry = self.deployment.keys.get(msg.key) if isinstance(msg.key, str) else None
        if entry is None or msg.stigmergy != self.deployment.buzz_stigmergy:
            self.drops[UNMAPPED] += 1
            return None
        op = Op.PUT if msg.op is BuzzOp.PUT else Op.GET
        self._highest[entry.key] = max(self._highest.get(entry.key, 0), msg.timestamp)
        if msg.value is None and op is Op.GET and msg.timestamp == 0:
            return Message(Op.GET, entry.key, 0, 0, msg.robot)
        raw = self.deployment.raw_from_buzz(msg.value, entry.value_type)
        if raw is None:
            self.drops[UNMAPPED] += 1
            return None
        return Message(op, entry.key, raw, msg.timestamp, msg.robot)

    def from_ours(self, msg: Message) -> BuzzVstig | None:
        entry = self.deployment.by_key.get(msg.key)
        if entry is None:
            self.drops[UNMAPPED] += 1
            return None
        if self._wrapped(entry.key, msg.timestamp):
            self.drops["buzz_wrap"] += 1
            return None
        op = BuzzOp.PUT if msg.op is Op.PUT else BuzzOp.QUERY
        stigmergy = self.deployment.buzz_stigmergy
        if op is BuzzOp.QUERY and msg.timestamp == 0:
            return BuzzVstig(op, stigmergy, entry.name, None, 0, msg.robot)
        value = self.deployment.buzz_from_raw(msg.value, entry.value_type)
        if value is None:
            self.drops[UNMAPPED] += 1
            return None
        return BuzzVstig(op, stigmergy, entry.name, value, msg.timestamp, msg.robot)


class BittyBuzzTranslator:
    def __init__(self, deployment: Deployment, drops: Counters | None = None,
                 threshold: int = BBZ_LAMPORT_THRESHOLD) -> None:
        self.deployment = deployment
        self.drops = drops if drops is not None else Counters()
        self.clock = LamportBridge(threshold)
        self.held: set[int] = set()  # our keys the Kilobots hold: heard from them, or sent to them
        self._repair: set[int] = set()  # keys some Kilobot showed it lacks our version of

    def to_ours(self, msg: BbzVstig) -> Message | None:
        """What our side gets from one Kilobot message, or None (unmapped, or nothing new).

        A Kilobot that shows it lacks our version (a query for a key it does not hold,
        an older lamport, a version that lost a conflict) becomes our empty GET for the
        key: the engine answers it with its entry, and `from_ours` then sends that entry
        back even though the anchor says the Kilobots have it.
        """
        entry = self.deployment.by_bbz_id.get(msg.key)
        if entry is None:
            self.drops[UNMAPPED] += 1
            return None
        if msg.value_type == BbzType.NIL and msg.op is BbzOp.QUERY and msg.lamport == 0:
            self._repair.add(entry.key)  # "who knows this key?": that robot lacks it
            return Message(Op.GET, entry.key, 0, 0, msg.robot)
        raw = self.deployment.raw_from_bbz(msg.value_type, msg.value, entry.value_type)
        if raw is None:
            self.drops[UNMAPPED] += 1
            return None
        self.held.add(entry.key)
        verdict, anchor = self.clock.from_kilobots(entry.key, msg.lamport, (msg.value_type, msg.value), msg.robot)
        if verdict is Verdict.NEWER:
            self._repair.discard(entry.key)
            return Message(Op.PUT if msg.op is BbzOp.PUT else Op.GET, entry.key, raw, anchor.timestamp, msg.robot)
        self.drops[verdict.value] += 1
        if verdict is Verdict.REPEAT:
            return None
        self._repair.add(entry.key)
        return Message(Op.GET, entry.key, 0, 0, msg.robot)

    def from_ours(self, msg: Message) -> BbzVstig | None:
        """The PUT that gives the Kilobots our version, or None (unmapped, guarded, or already theirs)."""
        entry = self.deployment.by_key.get(msg.key)
        if entry is None or entry.bbz_id is None:
            self.drops[UNMAPPED] += 1
            return None
        if msg.timestamp == 0:
            self.drops["guard_query"] += 1  # an empty GET would plant nil on Kilobots that lack the key
            return None
        if entry.key not in self.held and len(self.held) >= self.deployment.bbz_capacity:
            self.drops["guard_capacity"] += 1
            return None
        tagged = self.deployment.bbz_from_raw(msg.value, entry.value_type)
        if tagged is None:
            self.drops[UNMAPPED] += 1
            return None
        lamport = self.clock.to_kilobots(entry.key, msg.timestamp, tagged, msg.robot)
        if lamport is None:
            anchor = self.clock.anchors[entry.key]
            if entry.key not in self._repair or (anchor.timestamp, anchor.value) != (msg.timestamp, tagged):
                return None
            lamport = anchor.lamport  # the version they lack, at the lamport the anchor keeps for it
        self._repair.discard(entry.key)
        self.held.add(entry.key)
        return BbzVstig(BbzOp.PUT, msg.robot, entry.bbz_id, tagged[0], tagged[1], lamport)
