"""Zenoh framing: the key space and the sample payload (normative text: firmware_spec/SPEC.md, "Zenoh").

This module is the one owner of how the stigmergy rides on Zenoh::

    key expression   vstig/<swarm>/<stigmergy>/<gateway id>      e.g. vstig/lab/0/200
    payload          N >= 1 wire messages of 8 bytes, back to back (8*N bytes),
                     or 0xA1 then N >= 1 authenticated records of 20 bytes (1+20*N: never 8*N; SPEC.md 10.5)

Every gateway publishes under its own key and subscribes to
`vstig/<swarm>/<stigmergy>/*`, so each one hears every other on one broadcast
medium, and the last chunk of the key names the sender (as the CAN ID does).
One flush of the gateway's queue travels as one sample: a busy gateway sends a
packet per tick, not one per message.

Pure: no Zenoh import. A unit is a `ZenohSample` (key, payload); the transport
turns Zenoh's samples into these.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from ..auth import RECORD_SIZE, Tagged, decode_batch, encode_batch
from ..counters import Counters
from ..wire import MESSAGE_SIZE, DecodeError, Message, decode_many, encode
from .base import Framing

__all__ = ["KEY_ROOT", "MAX_GATEWAY", "MAX_SAMPLE", "MAX_STIGMERGY", "ZenohFraming", "ZenohKeySpace", "ZenohSample",
           "check_swarm"]

KEY_ROOT = "vstig"
MAX_STIGMERGY = 0xFFFF  # Buzz numbers stigmergies with 16 bits
MAX_GATEWAY = 0xFFFF  # a gateway is named by its robot id
MAX_SAMPLE = 64 * 1024  # payload bytes a receiver takes by default (8,192 messages); we never send more
_SWARM = re.compile(r"[A-Za-z0-9_.-]+\Z")  # one key-expression chunk with no wildcard or special character


def check_swarm(swarm: str) -> str:
    """The swarm name, if it can be one chunk of a key expression; ValueError naming it otherwise."""
    if not isinstance(swarm, str) or not _SWARM.match(swarm):
        raise ValueError(f"swarm name {swarm!r} must be letters, digits, '_', '.' or '-' (it is one chunk "
                         "of the key expression vstig/<swarm>/...)")
    return swarm


@dataclass(frozen=True, slots=True)
class ZenohSample:
    """One Zenoh sample as the link sees it: the key it was published under, its payload, and the id of the
    session it came from, where the transport can tell (its stamp names a session connected to ours; None: it
    cannot, and the sample's link is its only source)."""

    key: str
    payload: bytes
    source: str | None = None


@dataclass(frozen=True, slots=True)
class ZenohKeySpace:
    swarm: str
    stigmergy: int = 0

    def __post_init__(self) -> None:
        check_swarm(self.swarm)
        if isinstance(self.stigmergy, bool) or not isinstance(self.stigmergy, int) \
                or not 0 <= self.stigmergy <= MAX_STIGMERGY:
            raise ValueError(f"stigmergy must be 0..{MAX_STIGMERGY}, got {self.stigmergy!r}")

    @classmethod
    def of_key(cls, key: str) -> ZenohKeySpace:
        """The space a key vstig/<swarm>/<stigmergy>/<gateway> belongs to; ValueError for any other key."""
        parts = key.split("/")
        if len(parts) != 4 or parts[0] != KEY_ROOT or not parts[2].isdigit() or not parts[2].isascii():
            raise ValueError(f"{key!r} is not a vstig key (vstig/<swarm>/<stigmergy>/<gateway id>)")
        return cls(parts[1], int(parts[2]))

    @property
    def prefix(self) -> str:
        return f"{KEY_ROOT}/{self.swarm}/{self.stigmergy}/"

    @property
    def subscription(self) -> str:
        """The key expression that matches every gateway of this swarm and stigmergy."""
        return f"{self.prefix}*"

    @property
    def clock_prefix(self) -> str:
        """Where the swarm's sessions answer for their clocks: vstig/<swarm>/clock/<clock id> (not a stigmergy)."""
        return f"{KEY_ROOT}/{self.swarm}/clock"

    def key(self, gateway: int) -> str:
        if isinstance(gateway, bool) or not isinstance(gateway, int) or not 0 <= gateway <= MAX_GATEWAY:
            raise ValueError(f"a gateway id is 0..{MAX_GATEWAY}, got {gateway!r}")
        return f"{self.prefix}{gateway}"

    def gateway_of(self, key: str) -> int | None:
        """The publishing gateway's id, or None for a key outside this space (or not a plain decimal id)."""
        if not key.startswith(self.prefix):
            return None
        tail = key[len(self.prefix):]
        if not tail.isdigit() or not tail.isascii() or (len(tail) > 1 and tail[0] == "0"):
            return None
        gateway = int(tail)
        return gateway if gateway <= MAX_GATEWAY else None


class ZenohFraming(Framing[ZenohSample]):
    """Batches of 8-byte messages in samples; decodes what any gateway of the swarm publishes.

    `sender` is this gateway's id, the last chunk of the key it publishes under.
    Drops (counted, never raised): `foreign_key` (a key outside the space),
    `bad_length` (a payload that is empty, or neither 8*N bytes nor a whole tagged batch).
    """

    names_senders = True  # the key a sample is published under ends with the gateway's id
    names_sources = True  # each sample says which session published it
    capture_medium = "zenoh"  # our zenoh line capture: samples keep their keys
    narrows = True  # a cut sample keeps its key (its sender)
    carries_tags = True

    name = "zenoh"

    def __init__(self, space: ZenohKeySpace, sender: int) -> None:
        self.space = space
        self.sender = sender
        self.own_key = space.key(sender)
        self.drops = Counters()

    def encode(self, msg: Message) -> list[ZenohSample]:
        return [ZenohSample(self.own_key, encode(msg))]

    def encode_batch(self, messages: Iterable[Message]) -> list[ZenohSample]:
        """One sample for the whole batch (none for an empty one); one per MAX_SAMPLE bytes of a huge batch."""
        payload = b"".join(map(encode, messages))
        return [ZenohSample(self.own_key, payload[i:i + MAX_SAMPLE]) for i in range(0, len(payload), MAX_SAMPLE)]

    def encode_tagged(self, records: Sequence[Tagged]) -> list[ZenohSample]:
        """One tagged batch for all `records` (none for no records); one per MAX_SAMPLE bytes of a huge one."""
        per_sample = (MAX_SAMPLE - 1) // RECORD_SIZE
        return [ZenohSample(self.own_key, encode_batch(list(records[i:i + per_sample])))
                for i in range(0, len(records), per_sample)]

    def feed(self, unit: ZenohSample) -> list[Message]:
        payload = unit.payload
        if payload and not len(payload) % MESSAGE_SIZE and self.space.gateway_of(unit.key) is not None:
            return decode_many(payload)  # the untagged batch, without the pairs
        return [msg for msg, _ in self.feed_tagged(unit)]

    def feed_tagged(self, unit: ZenohSample) -> list[tuple[Message, Tagged | None]]:
        if self.space.gateway_of(unit.key) is None:
            self.drops["foreign_key"] += 1
            return []
        payload = unit.payload
        if payload and not len(payload) % MESSAGE_SIZE:
            return [(msg, None) for msg in decode_many(payload)]
        try:
            return [(record.message, record) for record in decode_batch(payload)]
        except DecodeError:
            self.drops["bad_length"] += 1
            return []

    def sender_of(self, unit: ZenohSample) -> int | None:
        return self.space.gateway_of(unit.key)

    def source_of(self, unit: ZenohSample) -> str | None:
        """The publishing session, if connected to ours: a peer may claim any gateway id in its keys, and any id in
        its stamps, but it cannot make up a session connected to ours per sample (transports/zenoh.py)."""
        return unit.source

    def narrow(self, unit: ZenohSample, messages: list[Message]) -> ZenohSample | None:
        """The sample under its own key carrying only `messages`; None for none."""
        payload = b"".join(map(encode, messages))
        return ZenohSample(unit.key, payload) if payload else None

    def tick(self) -> None:
        """Samples arrive whole: nothing to expire."""
