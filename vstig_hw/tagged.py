"""A gateway's engine with tags beside it (SPEC.md 10.4 and 10.6): pure, no I/O, the engine itself unchanged.

C twin: firmware_spec/libvstig/vstig_tagged.c, and vstig_hw/_cext/tags.c over it (a compiled Engine given the
swarm key); held equal by tests/spec/test_spec_c_tagged.py and tests/native.

`TaggedStigmergy` wraps a `Stigmergy` for a gateway that holds the swarm key. Every message it is fed comes
with the policy of the link that heard it and its record's epoch and tag, if the link carries them. It checks
the tag against the writer's key, refuses what the policy refuses (counted by reason and claimed writer),
orders tagged entries by (epoch, timestamp) so a replayed old write loses across a wrap too, and keeps each
stored entry's epoch and tag, so `record_of` gives every message the engine drains its writer's proof again.
A gateway without the swarm key never builds one: the engine's own path costs nothing more.
"""

from __future__ import annotations

import enum
from collections import Counter
from typing import NamedTuple

from .auth import SwarmKeys, Tagged, next_epoch, tagged_newer
from .engine import Entry, Outcome, Stigmergy
from .timestamps import TS_NONE, is_newer
from .wire import Message, Op

__all__ = ["AuthPolicy", "Refusal", "TaggedStigmergy"]


class AuthPolicy(enum.Enum):
    """What a link does with untagged messages and bad tags (SPEC.md 10.6)."""

    REQUIRE = "require"
    PREFER = "prefer"
    OFF = "off"

    @classmethod
    def parse(cls, text: str) -> AuthPolicy:
        """The policy named `text`; ValueError naming it and the choices."""
        try:
            return cls(text)
        except ValueError:
            raise ValueError(f"auth={text!r}: must be one of require, prefer, off") from None


class Refusal(enum.Enum):
    """Why a message was refused before the engine saw it (the counters' names)."""

    UNTAGGED = "drop_untagged"
    BAD_TAG = "drop_bad_tag"


class _Proof(NamedTuple):
    entry: Entry  # the entry these belong to: the engine may have moved on without us
    epoch: int
    tag: bytes | None  # None: kept untagged (a link with policy prefer or off)


class TaggedStigmergy:
    """One gateway's view of one stigmergy, with the epoch and tag of every entry it holds."""

    def __init__(self, engine: Stigmergy, keys: SwarmKeys) -> None:
        self.engine = engine
        self.keys = keys
        self.refused: Counter[tuple[Refusal, int]] = Counter()  # (reason, claimed writer) -> messages
        self.replays = 0  # tagged messages older than the entry by epoch: lost, as any old write does
        self._proofs: dict[int, _Proof] = {}

    # -- the gateway's own writes ---------------------------------------------
    def put(self, key: int, value: int) -> None:
        """A write of this gateway (robot `engine.robot_id`), tagged with its own key."""
        before = self._epoch_entry(key)
        self.engine.put(key, value)
        self._tag_own(key, before)

    # -- what the links heard -------------------------------------------------
    def receive(self, msg: Message, policy: AuthPolicy, epoch: int | None = None,
                tag: bytes | None = None, *, checked: bool = False) -> Outcome | Refusal:
        """Apply `msg` heard on a link with `policy`; `epoch` and `tag` are its record's, None when untagged.
        `checked`: the caller verified the tag already (a gateway's check before its guard): not again."""
        key, ts = msg.key, msg.timestamp
        if ts == TS_NONE:  # an empty GET (or an invalid PUT) shows no entry: nothing to prove
            return self.engine.receive(msg)
        proven = tag is not None and epoch is not None and policy is not AuthPolicy.OFF
        if tag is not None and epoch is not None and proven and not checked \
                and not self.keys.verify(Tagged(msg, epoch, tag)):
            self.refused[Refusal.BAD_TAG, msg.robot] += 1
            return Refusal.BAD_TAG
        if not proven and policy is AuthPolicy.REQUIRE:
            self.refused[Refusal.UNTAGGED, msg.robot] += 1
            return Refusal.UNTAGGED
        held = self._epoch_entry(key)
        local = held[1]
        if not proven or epoch is None:  # untagged: the held entry's epoch, one more if it wrapped past it
            wrapped = local is not None and is_newer(ts, local.timestamp) and ts < local.timestamp
            epoch = held[0] + wrapped
        if local is not None and self._older(epoch, msg, held[0], local, proven):
            if proven:
                self.replays += 1
            if msg.op is Op.GET:  # answer it with our entry, as row 5 does
                return self.engine.receive(Message(Op.GET, key, 0, TS_NONE, msg.robot))
            return Outcome.STALE
        outcome = self.engine.receive(msg)
        self._note(key, msg, epoch, tag if proven else None, held)
        return outcome

    def _older(self, epoch: int, msg: Message, held_epoch: int, local: Entry, proven: bool) -> bool:
        """True when the message loses to the entry held before the engine sees it: older by (epoch, timestamp)
        (SPEC.md 10.4), or an untagged rival of a tagged entry at the same (epoch, timestamp) on a prefer link."""
        if tagged_newer(held_epoch, local.timestamp, epoch, msg.timestamp):
            return True
        same = (held_epoch, local.timestamp) == (epoch, msg.timestamp)
        proof = self._proofs.get(msg.key)
        return same and not proven and proof is not None and proof.tag is not None and proof.entry == local \
            and msg.robot != local.robot

    def _note(self, key: int, msg: Message, epoch: int, tag: bytes | None, held: tuple[int, Entry | None]) -> None:
        """Keep the proof of whatever the engine now holds for `key`."""
        now = self.engine.entry(key)
        if now is None or now == held[1]:
            return
        if now == Entry(msg.value, msg.timestamp, msg.robot):
            self._proofs[key] = _Proof(now, epoch, tag)
        elif now.robot == self.engine.robot_id:  # a merge we wrote (row 7): a new write of ours
            self._tag_own(key, held)
        else:  # the local entry kept after a conflict: its proof stands
            proof = self._proofs.get(key)
            if proof is None or proof.entry != now:
                self._proofs.pop(key, None)

    def _epoch_entry(self, key: int) -> tuple[int, Entry | None]:
        """(epoch, entry) the engine holds for `key`; epoch 0 for a key not held or held without a proof."""
        entry = self.engine.entry(key)
        proof = self._proofs.get(key)
        return (proof.epoch if proof is not None and proof.entry == entry else 0), entry

    def _tag_own(self, key: int, before: tuple[int, Entry | None]) -> None:
        entry = self.engine.entry(key)
        assert entry is not None
        old_epoch, old = before
        epoch = next_epoch(old_epoch, old.timestamp if old else TS_NONE, entry.timestamp)
        tagged = self.keys.tag(Message(Op.PUT, key, *entry), epoch)
        self._proofs[key] = _Proof(entry, epoch, tagged.tag)

    # -- what to send ---------------------------------------------------------
    def record_of(self, msg: Message) -> Tagged | None:
        """`msg` (drained from the engine) with its entry's epoch and writer's tag; None when the gateway holds
        no verified proof of that entry, which a link that requires tags must then not carry."""
        if msg.timestamp == TS_NONE:
            return Tagged(msg, 0, bytes(8))
        proof = self._proofs.get(msg.key)
        if proof is None or proof.tag is None or proof.entry != Entry(msg.value, msg.timestamp, msg.robot):
            return None
        return Tagged(msg, proof.epoch, proof.tag)
