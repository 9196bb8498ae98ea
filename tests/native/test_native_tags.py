"""The compiled Engine given the swarm key against SignedEngine, its Python reference (vstig_hw/_cext/tags.c):
random streams of honest tagged writes across the timestamp wrap, forgeries, replays, untagged writes, empty GETs
and the node's own puts, under every policy, checked as `Signing.check` checks them and then received, give the
same outcomes, tables, drained messages, records and counts."""

from __future__ import annotations

import random
from types import ModuleType
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw.auth import SwarmKeys, Tagged
from vstig_hw.gateway.compiled import Compiled
from vstig_hw.gateway.signing import SignedEngine
from vstig_hw.tagged import AuthPolicy
from vstig_hw.timestamps import next_timestamp
from vstig_hw.wire import Message, Op

MASTER = bytes(range(0xA0, 0xC0))
NODE = 200
WRITERS = [5, 7, 99, 1029]  # 5 and 1029 share a place of the compiled engine's writer-key cache (1024 places)


def passes(keys: SwarmKeys, msg: Message, record: Tagged | None, policy: AuthPolicy) -> bool:
    """Whether `Signing.check` lets the message through (its `_refusal`)."""
    if msg.timestamp == 0 or policy is AuthPolicy.OFF:
        return True
    return keys.verify(record) if record is not None else policy is not AuthPolicy.REQUIRE


def traffic(seed: int, keys: SwarmKeys, steps: int) -> list[tuple[Any, ...]]:
    """("put", key, value), ("drain",) or ("recv", policy, msg, record or None)."""
    rng = random.Random(seed)
    clocks = {key: (0, rng.choice([0, 65520])) for key in range(4)}
    heard: list[Tagged] = []
    calls: list[tuple[Any, ...]] = []
    for _ in range(steps):
        roll, key, policy = rng.random(), rng.randrange(4), rng.choice(list(AuthPolicy))
        epoch, ts = clocks[key]
        if roll < 0.1:
            calls.append(("put", key, rng.randrange(1 << 16)))
            continue
        if roll < 0.2:
            calls.append(("drain",))
            continue
        record: Tagged | None
        if roll < 0.55:  # honest, its epoch stepping at the wrap
            following = next_timestamp(ts)
            epoch, ts = epoch + (1 if ts and following < ts else 0), following
            clocks[key] = (epoch, ts)
            record = keys.tag(Message(Op.PUT, key, rng.randrange(1 << 16), ts, rng.choice(WRITERS)), epoch)
            heard.append(record)
        elif roll < 0.65 and heard:  # a replay, maybe as a GET
            old = rng.choice(heard)
            record = Tagged(old.message.replace(op=rng.choice([Op.PUT, Op.GET])), old.epoch, old.tag)
        elif roll < 0.75:  # a forgery
            msg = Message(Op.PUT, key, rng.randrange(1 << 16), next_timestamp(ts), rng.choice(WRITERS))
            record = Tagged(msg, epoch, bytes(rng.randrange(256) for _ in range(8)))
        elif roll < 0.9:  # untagged
            msg = Message(rng.choice([Op.PUT, Op.GET]), key, rng.randrange(1 << 16),
                          rng.choice([ts, next_timestamp(ts), 0]), rng.choice([5, 99, 250]))
            calls.append(("recv", policy, msg, None))
            continue
        else:  # an empty GET
            record = Tagged(Message(Op.GET, key, 0, 0, 5), 0, bytes(8))
        calls.append(("recv", policy, record.message, record))
    return calls


def run(engine: Any, keys: SwarmKeys, calls: list[tuple[Any, ...]]) -> list[object]:
    """What each call gives, as `Signing` drives its engine: records and policy set per unit, checked first."""
    records: dict[Message, Tagged] = {}
    engine.records = records
    seen: list[object] = []
    for call in calls:
        if call[0] == "put":
            engine.put(call[1], call[2])
            seen.append(engine.entry(call[1]))
        elif call[0] == "drain":
            seen.append([(msg, engine.record_of(msg)) for msg in engine.drain()])
        else:
            _, policy, msg, record = call
            records.clear()
            if record is not None and policy is not AuthPolicy.OFF:
                records[msg] = record
            engine.policy = policy
            seen.append(engine.receive(msg) if passes(keys, msg, record, policy) else "refused")
            seen.append(engine.entry(msg.key))
    seen.append(engine.counts)
    seen.append(sorted(engine.entries()))
    return seen


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32), steps=st.integers(20, 300))
def test_signed_engine_twin_equals_signed_engine(compiled: ModuleType, seed: int, steps: int) -> None:
    keys = SwarmKeys(MASTER, 3)
    calls = traffic(seed, keys, steps)
    want = run(SignedEngine(NODE, keys), keys, calls)
    got = run(Compiled().signed_engine(NODE, None, keys), keys, calls)
    for i, (have, expected) in enumerate(zip(got, want, strict=True)):
        assert have == expected, f"seed {seed}, step {i}"


def test_the_twin_keeps_proofs_a_replay_loses_and_refuses_a_stranger_policy(compiled: ModuleType) -> None:
    keys = SwarmKeys(MASTER)
    engine = Compiled().signed_engine(NODE, None, keys)
    first, second = keys.tag(Message(Op.PUT, 1, 10, 65535, 5), 0), keys.tag(Message(Op.PUT, 1, 11, 1, 5), 1)
    engine.policy = AuthPolicy.REQUIRE
    for record in (first, second, first):  # the old write replayed after the wrap: older by epoch, it loses
        engine.records = {record.message: record}
        engine.receive(record.message)
    assert engine.entry(1) == (11, 1, 5)
    assert engine.record_of(second.message) == second
    assert engine.record_of(first.message) is None  # not the held entry: no proof to send with it
    assert engine.counts[next(o for o in engine.counts if o.name == "STALE")] == 1
    try:
        engine.policy = "require"  # type: ignore[assignment]
    except TypeError as error:
        assert "policy must be one of" in str(error)
    else:
        raise AssertionError("a policy that is not AuthPolicy's was taken")
