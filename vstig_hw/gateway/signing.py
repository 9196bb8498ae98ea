"""A gateway that holds the swarm key (SPEC.md 10.6): tags checked by each link's policy, entries kept with their
writers' proofs, and every message sent with its entry's proof on the links that carry tags.

C twin: vstig_hw/_cext/tags.c (the engine, and the check of a unit the compiled delivery decoded, over libvstig's
vstig_tagged); held equal by tests/native/test_native_tags.py.

The Node builds a `Signing` when given the swarm key. Each link's units decode with their records (`decoder`: its
framing's, or its compiled Receiver's); `check` refuses, before the guard, what the link's policy refuses: an
untagged message on an `auth=require` link (`drop_untagged`), a tag that does not check out on a `require` or
`prefer` link (`drop_bad_tag`); `refuse` counts each on the link and by claimed writer, tells the Node's `refused`
listeners (sniff's refused column, the roster) and logs once per writer and episode (the compiled delivery checks
in C and calls it for each refusal). The engine is a `SignedEngine` (or its compiled twin): the engine with a
`TaggedStigmergy` beside it, so it orders tagged entries by (epoch, timestamp) and keeps each entry's proof, taken
from the records of the unit's messages that passed; `record_of` gives the outlets every message's proof again
(`Link.record_of`, or the compiled Encoder's `send_tags`), and a link that requires tags never carries an entry
without one (`held_unverified`).
"""

from __future__ import annotations

import functools
from collections import Counter
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from ..auth import SwarmKeys, Tagged
from ..engine import ConflictResolver, Outcome, Stigmergy
from ..links import Heard, Link
from ..tagged import AuthPolicy, Refusal, TaggedStigmergy
from ..timestamps import TS_NONE
from ..wire import Message

if TYPE_CHECKING:
    from .._vstig import Engine as CompiledEngine
    from .._vstig import Receiver
    from .compiled import Compiled

__all__ = ["EPISODE_GAP", "SignedEngine", "Signing", "unkeyed_policy"]

EPISODE_GAP = 10.0  # seconds without a refusal of a writer that end its episode: its next refusal is logged again
_REFUSED = tuple[str, int]  # (drop counter, claimed writer)


def unkeyed_policy(links: Sequence[Link[Any]]) -> str | None:
    """The complaint for links that check tags on a node without the swarm key; None when none does."""
    asking = [link for link in links if link.auth is not AuthPolicy.OFF]
    if not asking:
        return None
    return f"link {asking[0].name!r} has auth={asking[0].auth.value}: checking tags needs the swarm key " \
        "(--swarm-key FILE, swarm_key=)"


class SignedEngine(Stigmergy):
    """The engine of a gateway with the swarm key: what it receives goes through `tagged` under the policy and
    with the record of the link it came on (`policy`, `records`, set as each batch is checked); its own writes
    are tagged with its own key. `TaggedStigmergy` calls the engine's own `receive` and `put` beneath these."""

    def __init__(self, robot_id: int, keys: SwarmKeys, onconflict: ConflictResolver | None = None) -> None:
        super().__init__(robot_id, onconflict)
        self.tagged = TaggedStigmergy(self, keys)
        self.policy = AuthPolicy.OFF
        self.records: dict[Message, Tagged] = {}  # the batch being received: message -> its record
        self._beneath = False  # inside `tagged`: its calls are the engine's own

    def put(self, key: int, value: int) -> None:
        if self._beneath:
            return super().put(key, value)
        self._beneath = True
        try:
            self.tagged.put(key, value)
        finally:
            self._beneath = False

    def receive(self, msg: Message) -> Outcome:
        if self._beneath:
            return super().receive(msg)
        record = self.records.get(msg)
        self._beneath = True
        try:
            done = self.tagged.receive(msg, self.policy, *((None, None) if record is None else record[1:]),
                                       checked=True)  # `Signing.check` verified every record it left in
        finally:
            self._beneath = False
        return done if isinstance(done, Outcome) else Outcome.STALE  # `Signing.check` refused those already

    def record_of(self, msg: Message) -> Tagged | None:
        return self.tagged.record_of(msg)

    @property
    def replays(self) -> int:
        """Tagged messages older than the entry by (epoch, timestamp): lost, and counted as stale."""
        return self.tagged.replays

    @property
    def counts(self) -> dict[Outcome, int]:
        """The engine's outcomes, a replayed old write (older by epoch and timestamp, SPEC.md 10.4) as stale."""
        counts = super().counts
        counts[Outcome.STALE] += self.tagged.replays
        return counts


class Signing:
    """The swarm key's part of one Node: decoding with records, checking by policy, proofs for the outlets."""

    def __init__(self, keys: SwarmKeys, links: Sequence[Link[Any]]) -> None:
        self.keys = keys
        self.links = links
        self.engine: SignedEngine | CompiledEngine | None = None  # the Node's engine, if it has one (`engine_for`)
        self.records: dict[Message, Tagged] = {}  # of the unit just decoded: those that passed `check`, for the engine
        self._unit: list[Tagged | None] = []  # the unit's record of each message, in the order decoded
        self.refused: Counter[_REFUSED] = Counter()
        self.warnings: list[str] = []  # for the caller to print (and clear), as the guard's
        self._last_refusal: dict[tuple[str, str, int], float] = {}  # (link, reason, writer) -> when

    def engine_for(self, robot_id: int, onconflict: ConflictResolver | None,
                   compiled: Compiled | None = None) -> Stigmergy:
        """The Node's engine: a SignedEngine, or its compiled twin when the Node's parts are `compiled`."""
        engine = SignedEngine(robot_id, self.keys, onconflict) if compiled is None else \
            compiled.signed_engine(robot_id, onconflict, self.keys)
        engine.records = self.records
        self.engine = engine
        return engine

    def decoder(self, link: Link[Any], receiver: Receiver | None = None) -> Callable[[Any], list[Message]]:
        """Link `link`'s decoding: its framing's messages (its compiled `receiver`'s, which then decodes for both
        deliveries and checks by the link's policy on the compiled one), each one's record kept until the next unit."""
        unit_records = self._unit
        feed_tagged: Callable[[Any], list[tuple[Message, Tagged | None]]]
        if receiver is not None:
            receiver.check_tags(list(AuthPolicy).index(link.auth), functools.partial(self.refuse, link))
            feed = receiver.feed_tagged

            def compiled_feed_tagged(unit: Any) -> list[tuple[Message, Tagged | None]]:
                return [(msg, None if proof is None else Tagged(msg, *proof)) for msg, proof in feed(unit)]

            feed_tagged = compiled_feed_tagged
        else:
            feed_tagged = link.feed_tagged

        def decode(unit: Any) -> list[Message]:
            unit_records.clear()
            messages = []
            for msg, record in feed_tagged(unit):
                messages.append(msg)
                unit_records.append(record)
            return messages

        return link.decode if link.transmit_only else decode

    def record_of(self, link: Link[Any]) -> Callable[[Message], Tagged | None] | None:
        """What link `link`'s outlet sends each message with: its entry's record, on a link that carries tags and
        checks them (None: messages go untagged)."""
        if self.engine is None or link.auth is AuthPolicy.OFF or not link.carries_tags:
            return None
        return self.engine.record_of

    def check(self, link: Link[Any], messages: list[Message], t: float, sender: int | None,
              refused: Sequence[Callable[[Heard, str], None]]) -> list[Message]:
        """The messages of one unit heard on `link` that its policy lets in; the others counted, told to the
        `refused` listeners and logged. The engine receives what passes under this link's policy."""
        policy = link.auth
        records = self.records
        records.clear()
        if self.engine is not None:
            self.engine.policy = policy
        if policy is AuthPolicy.OFF:
            return messages  # tags ignored: kept untagged
        kept = []
        for msg, record in zip(messages, self._unit, strict=True):
            reason = self._refusal(msg, record, policy)
            if reason is not None:
                self.refuse(link, msg, reason, t, sender, refused)
                continue
            kept.append(msg)
            if record is not None:  # only a record that passed: a forged copy beside an honest one is not kept
                records[msg] = record
        return kept

    def refuse(self, link: Link[Any], msg: Message, reason: str, t: float, sender: int | None,
               refused: Sequence[Callable[[Heard, str], None]]) -> None:
        """A message `link`'s policy refused: counted on the link and by claimed writer, logged once per episode,
        told to the `refused` listeners (the compiled delivery calls this for each one it refuses)."""
        self._count(link, reason, msg.robot, t)
        for listener in refused:
            listener(Heard(msg, link.name, t, sender), reason)

    def _refusal(self, msg: Message, record: Tagged | None, policy: AuthPolicy) -> str | None:
        if msg.timestamp == TS_NONE:  # an empty GET shows no entry: nothing to prove
            return None
        if record is None:
            return Refusal.UNTAGGED.value if policy is AuthPolicy.REQUIRE else None
        return None if self.keys.verify(record) else Refusal.BAD_TAG.value

    def _count(self, link: Link[Any], reason: str, writer: int, t: float) -> None:
        link.counters[reason] += 1
        self.refused[reason, writer] += 1
        episode = (link.name, reason, writer)
        last = self._last_refusal.get(episode)
        self._last_refusal[episode] = t
        if last is None or t - last > EPISODE_GAP:
            what = "untagged writes" if reason == Refusal.UNTAGGED.value else "writes whose tag does not check out"
            self.warnings.append(f"warning: {link.name}: refusing {what} claiming robot {writer} ({reason}; "
                                 f"counted, logged again after {EPISODE_GAP:g} s without one)")
