"""TaggedStigmergy (SPEC.md 10.4, 10.6) as data in, data out: each attack refused and counted, honest writes
stored with their writer's proof, which every re-broadcast carries again."""

from __future__ import annotations

import pytest

from vstig_hw.auth import SwarmKeys, Tagged, next_epoch, robot_key
from vstig_hw.engine import Entry, Outcome, Stigmergy
from vstig_hw.tagged import AuthPolicy, Refusal, TaggedStigmergy
from vstig_hw.wire import Message, Op

MASTER = bytes(range(0xA0, 0xC0))
KEYS = SwarmKeys(MASTER)
GATEWAY, HONEST, OTHER = 200, 5, 7
REQUIRE, PREFER, OFF = AuthPolicy.REQUIRE, AuthPolicy.PREFER, AuthPolicy.OFF


def gateway() -> TaggedStigmergy:
    return TaggedStigmergy(Stigmergy(GATEWAY), KEYS)


def written(key: int, value: int, ts: int, robot: int = HONEST, epoch: int = 0, op: Op = Op.PUT) -> Tagged:
    """A record as its writer makes it (the writer holds only its own key)."""
    msg = Message(op, key, value, ts, robot)
    tagged = KEYS.tag(msg.replace(op=Op.PUT), epoch)
    return Tagged(msg, epoch, tagged.tag)


def feed(node: TaggedStigmergy, record: Tagged, policy: AuthPolicy = REQUIRE) -> Outcome | Refusal:
    return node.receive(record.message, policy, record.epoch, record.tag)


def test_an_honest_write_is_stored_and_relayed_with_its_writers_tag() -> None:
    node = gateway()
    record = written(3, 42, 1)
    assert feed(node, record) is Outcome.STORED
    assert node.engine.entry(3) == Entry(42, 1, HONEST)
    (relayed,) = node.engine.drain()
    assert node.record_of(relayed) == record and KEYS.verify(record)
    node.engine.get(3)  # a GET showing the entry carries the same proof
    (shown,) = node.engine.drain()
    assert shown.op is Op.GET and node.record_of(shown) == Tagged(shown, 0, record.tag)


def test_an_outsiders_untagged_write_is_refused_on_require_and_kept_on_off() -> None:
    node = gateway()
    outsider = Message(Op.PUT, 3, 666, 1, 99)
    assert node.receive(outsider, REQUIRE) is Refusal.UNTAGGED
    assert node.engine.entry(3) is None and node.refused == {(Refusal.UNTAGGED, 99): 1}
    assert node.receive(outsider, OFF) is Outcome.STORED
    (relayed,) = node.engine.drain()
    assert node.record_of(relayed) is None  # never onto a link that requires tags


@pytest.mark.parametrize(
    ("name", "forged"),
    [
        ("an outsider's guessed tag", Tagged(Message(Op.PUT, 3, 666, 1, HONEST), 0, bytes(8))),
        ("robot 7 writes as robot 5 with its own key",
         Tagged(Message(Op.PUT, 3, 666, 1, HONEST), 0,
                SwarmKeys(robot_key(MASTER, OTHER)).tag(Message(Op.PUT, 3, 666, 1, HONEST), 0).tag)),
        ("a relay changed the value", written(3, 42, 1)._replace(message=Message(Op.PUT, 3, 43, 1, HONEST))),
        ("a relay changed the epoch", written(3, 42, 1)._replace(epoch=1)),
    ],
)
@pytest.mark.parametrize("policy", [REQUIRE, PREFER])
def test_bad_tags_are_refused_and_counted_under_the_claimed_writer(name: str, forged: Tagged,
                                                                  policy: AuthPolicy) -> None:
    node = gateway()
    assert feed(node, forged, policy) is Refusal.BAD_TAG, name
    assert node.refused == {(Refusal.BAD_TAG, HONEST): 1} and node.engine.entry(3) is None
    assert feed(node, written(3, 42, 1), policy) is Outcome.STORED  # honest traffic intact


def test_a_replayed_old_write_loses() -> None:
    node = gateway()
    old = written(3, 10, 1)
    for ts in (1, 2, 3):
        feed(node, written(3, 10 * ts, ts))
    assert feed(node, old) is Outcome.STALE and node.engine.entry(3) == Entry(30, 3, HONEST)


def test_a_replay_across_the_wrap_loses_where_16_bit_order_would_let_it_win() -> None:
    recorded = written(3, 666, 60000)  # heard and kept by an attacker, epoch 0
    current = written(3, 42, 30000, epoch=1)  # the key wrapped once since
    plain = Stigmergy(GATEWAY)
    plain.receive(current.message)
    assert plain.receive(recorded.message) is Outcome.STORED  # the hole: 60000 is "newer" than 30000
    node = gateway()
    feed(node, current)
    assert feed(node, recorded) is Outcome.STALE and node.replays == 1
    assert node.engine.entry(3) == Entry(42, 30000, HONEST)
    replayed_get = written(3, 666, 60000, op=Op.GET)
    node.engine.drain()
    assert feed(node, replayed_get) is Outcome.ANSWERED  # answered with the current entry, as row 5 does
    (answer,) = node.engine.drain()
    assert node.record_of(answer) == current


def test_a_replay_half_a_counter_back_within_an_epoch_loses() -> None:
    node = gateway()
    feed(node, written(3, 42, 40000))
    assert feed(node, written(3, 666, 100)) is Outcome.STALE  # RFC 1982 alone: 100 is newer than 40000
    assert node.engine.entry(3) == Entry(42, 40000, HONEST)


def test_the_gateways_own_writes_are_tagged_and_step_the_epoch_at_the_wrap() -> None:
    node = gateway()
    feed(node, written(3, 1, 65535, epoch=4))
    node.put(3, 7)
    (mine,) = node.engine.drain()
    assert mine == Message(Op.PUT, 3, 7, 1, GATEWAY)
    record = node.record_of(mine)
    assert record is not None and record.epoch == next_epoch(4, 65535, 1) == 5 and KEYS.verify(record)


def test_prefer_keeps_untagged_marked_and_a_tagged_entry_wins_the_tie() -> None:
    node = gateway()
    assert node.receive(Message(Op.PUT, 3, 9, 1, 99), PREFER) is Outcome.STORED
    node.engine.drain()
    assert node.record_of(Message(Op.PUT, 3, 9, 1, 99)) is None
    assert feed(node, written(3, 42, 1, robot=HONEST), PREFER) is Outcome.CONFLICT  # 99 > 5 would win
    node2 = gateway()
    feed(node2, written(3, 42, 1, robot=HONEST), PREFER)
    assert node2.receive(Message(Op.PUT, 3, 9, 1, 99), PREFER) is Outcome.STALE  # higher id, but untagged
    assert node2.engine.entry(3) == Entry(42, 1, HONEST)


def test_off_ignores_tags_even_bad_ones() -> None:
    node = gateway()
    forged = Tagged(Message(Op.PUT, 3, 666, 1, HONEST), 0, bytes(8))
    assert feed(node, forged, OFF) is Outcome.STORED and not node.refused
    (relayed,) = node.engine.drain()
    assert node.record_of(relayed) is None


def test_empty_gets_need_no_tag_even_on_require() -> None:
    node = gateway()
    feed(node, written(3, 42, 1))
    node.engine.drain()
    assert node.receive(Message(Op.GET, 3, 0, 0, 99), REQUIRE) is Outcome.ANSWERED
    assert node.record_of(Message(Op.GET, 4, 0, 0, GATEWAY)) == Tagged(Message(Op.GET, 4, 0, 0, GATEWAY), 0, bytes(8))


def test_a_mixed_swarm_converges_on_the_honest_writes() -> None:
    """Site A hears robots on an `off` radio; A and B meet on a link that requires tags. The honest robot's
    tagged writes reach B with their proof; an outsider's untagged write stays at A, never relayed to B."""
    site_a, site_b = gateway(), TaggedStigmergy(Stigmergy(201), KEYS)
    feed(site_a, written(1, 11, 1), OFF)  # a tag on an off link is ignored: kept untagged
    feed(site_a, written(2, 22, 1), PREFER)
    site_a.receive(Message(Op.PUT, 3, 666, 1, 99), OFF)
    for msg in site_a.engine.drain():
        record = site_a.record_of(msg)
        if record is not None:
            feed(site_b, record, REQUIRE)
    assert site_b.engine.entry(2) == Entry(22, 1, HONEST)
    assert site_b.engine.entry(1) is None and site_b.engine.entry(3) is None and not site_b.refused
    site_a.receive(Message(Op.PUT, 3, 666, 1, 99), REQUIRE)
    assert site_a.refused == {(Refusal.UNTAGGED, 99): 1}


def test_policy_names() -> None:
    assert AuthPolicy.parse("require") is REQUIRE
    with pytest.raises(ValueError, match="auth='strict': must be one of require, prefer, off"):
        AuthPolicy.parse("strict")
