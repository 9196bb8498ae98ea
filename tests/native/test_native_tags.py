"""The compiled Engine given the swarm key against SignedEngine, its Python reference (vstig_hw/_cext/tags.c):
random streams of honest tagged writes across the timestamp wrap, forgeries, replays, untagged writes, empty GETs
and the node's own puts, under every policy, checked as `Signing.check` checks them and then received, give the
same outcomes, tables, drained messages, records and counts; and the whole compiled delivery (records decoded
from cobs8 and CAN FD units, checked by each link's policy, sent with each entry's record) against the Python
Node on such streams."""

from __future__ import annotations

import os
import random
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from types import ModuleType
from typing import Any

import can
import pytest
import test_native_gateway as gateway_twins  # its Node harness, not its tests
from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw.auth import SwarmKeys, Tagged, encode_batch
from vstig_hw.counters import Counters
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.framing.xbee import MAX_RECORDS_PER_FRAME, ModuleInfo, XBeeFraming, api_frame, receive_packet
from vstig_hw.gateway import assembly as assembly_module
from vstig_hw.gateway.compiled import Compiled
from vstig_hw.gateway.node import Node
from vstig_hw.gateway.signing import SignedEngine
from vstig_hw.links import parse
from vstig_hw.links.link import Link
from vstig_hw.tagged import AuthPolicy
from vstig_hw.timestamps import next_timestamp
from vstig_hw.wire import Message, Op, encode

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


# -- the whole compiled delivery against the Python Node ------------------------------------------------------------

# (name, framing, policy): records decoded and sent in C (cobs8, CAN FD, XBee) under each policy
SIGNED_LINKS = [("radio", "cobs8", AuthPolicy.REQUIRE), ("bus", "canfd", AuthPolicy.PREFER),
                ("plain", "cobs8", AuthPolicy.OFF), ("modules", "xbee", AuthPolicy.REQUIRE)]
XBEE_NP = 41  # the module's NP: 5 messages a frame, 2 records a tagged batch (0xA1 and 40 bytes)


def _signed_node(compiled: bool, refused: list[tuple[str, Message, str]]) -> Node:
    links = []
    for name, kind, policy in SIGNED_LINKS:
        framing: Any = (CanFraming(CanIdScheme(), sender=9, fd=True) if kind == "canfd" else
                        XBeeFraming() if kind == "xbee" else make_serial_framing(kind))
        link = Link(name, gateway_twins.MemoryTransport(name), framing, one_domain=kind == "canfd")
        link.auth = policy
        links.append(link)
    with pytest.MonkeyPatch.context() as patch:
        if not compiled:
            patch.setattr(assembly_module, "compiled_for", lambda relays, links: None)
        node = Node(links, 9, period=1.0, budget=None, swarm_keys=SwarmKeys(MASTER))
    assert (node._delivery.path is not None) == compiled
    links[3].framing.use_module(ModuleInfo(max_payload=XBEE_NP))  # as the module says at open, after the Node
    node.listen(refused=lambda heard, reason: refused.append((heard.link, heard.message, reason)))
    return node


def _units(rng: random.Random, kind: str, sent: list[tuple[Message, Tagged | None]]) -> list[Any]:
    """What a robot's radio or CAN node sends: each message as a record or untagged (cobs8 cut anywhere, XBee Receive
    Packets of a tagged batch or a message each, in one unit)."""
    if kind == "xbee":
        return [b"".join(api_frame(receive_packet(0x0013A20040A1B2C3, encode(msg) if record is None else
                                                  encode_batch([record]))) for msg, record in sent)]
    if kind == "canfd":
        robot = CanFraming(CanIdScheme(), sender=rng.choice([3, 4]), fd=True)
        return [frame for msg, record in sent
                for frame in (robot.encode_tagged([record]) if record is not None else robot.encode(msg))]
    framing = make_serial_framing(kind)
    stream = b"".join(b"".join(framing.encode_tagged([record]) if record is not None else framing.encode(msg))
                      for msg, record in sent)
    cuts = sorted(rng.sample(range(1, len(stream)), min(2, len(stream) - 1))) if len(stream) > 1 else []
    return [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]


def _stream(seed: int, keys: SwarmKeys, steps: int) -> list[tuple[Any, ...]]:
    """("heard", link, units' seed, [(message, record or None)]) and ("put", key, value), from `traffic`."""
    rng = random.Random(seed)
    script: list[tuple[Any, ...]] = []
    for call in traffic(seed, keys, steps):
        if call[0] == "put":
            script.append(call)
        elif call[0] == "recv":
            script.append(("heard", rng.randrange(len(SIGNED_LINKS)), rng.randrange(2**32), [call[2:]]))
        elif script and script[-1][0] == "heard":  # a drain: the messages since the last one in one unit
            script[-1] = (*script[-1][:3], script[-1][3] * rng.choice([1, 1, 2]))  # sometimes a copy of it too
    return script


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32), steps=st.integers(20, 200))
def test_the_compiled_delivery_with_tags_equals_the_python_node(compiled: ModuleType, seed: int, steps: int) -> None:
    """Random tagged, forged, replayed and untagged streams on links that require, prefer and ignore tags: the same
    table, counters, refusals (told and counted by writer) and bytes out."""
    keys = SwarmKeys(MASTER)
    told: tuple[list[tuple[str, Message, str]], list[tuple[str, Message, str]]] = ([], [])
    nodes = [_signed_node(False, told[0]), _signed_node(True, told[1])]
    try:
        for step in _stream(seed, keys, steps):
            for node in nodes:
                now = 1.0
                with node._lock:
                    if step[0] == "put":
                        assert node.seat is not None
                        node.seat.put(step[1], step[2])
                        node._outbound.spread(now)
                    else:
                        index, units = step[1], _units(random.Random(step[2]), SIGNED_LINKS[step[1]][1], step[3])
                        path = node._delivery.path
                        if path is None or not path.deliver(index, 1_700_000_000.0, units, now):
                            node._delivery.arrive(index, 1_700_000_000.0, units)
                            node._outbound.spread(now, 1 << index)
                gateway_twins._settled(node)
            pure, c = (gateway_twins._state(node) for node in nodes)
            assert c == pure, step
            assert told[1] == told[0], step
            assert nodes[1].signing is not None and nodes[0].signing is not None
            assert nodes[1].signing.refused == nodes[0].signing.refused, step
        signings = [node.signing for node in nodes]
        assert signings[0] is not None and signings[1] is not None and signings[1].warnings == signings[0].warnings
    finally:
        for node in nodes:
            gateway_twins._close(node)


# -- XBee: tagged batches (0xA1 and records) in Receive Packets -------------------------------------------------

def _xbee_rf(rng: random.Random, keys: SwarmKeys) -> bytes:
    """RF data: untagged messages, a tagged batch (some forged), or a batch of a wrong length (bad_length)."""
    msgs = [Message(Op.PUT, rng.randrange(8), rng.randrange(1 << 16), rng.randrange(1, 1 << 16), rng.choice(WRITERS))
            for _ in range(rng.randint(1, 3))]
    roll = rng.random()
    if roll < 0.3:
        return b"".join(encode(m) for m in msgs)
    records = [keys.tag(m, rng.randrange(3)) for m in msgs]
    if roll < 0.45:
        records[0] = Tagged(records[0].message, records[0].epoch, bytes(8))
    batch = encode_batch(records)
    return batch[:-rng.randint(1, 19)] if roll > 0.9 else batch


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32), auth=st.sampled_from(list(AuthPolicy)))
def test_the_xbee_receiver_reads_tagged_batches_as_the_framing(compiled: ModuleType, seed: int,
                                                               auth: AuthPolicy) -> None:
    """Receive Packets of messages, of tagged batches (SPEC.md 10.5) and of batches cut short, one or several a unit:
    `feed` gives the same messages and sender (a batch's without their tags), `feed_tagged` the same records on a
    link that checks tags, and the drops are the same."""
    rng, keys = random.Random(seed), SwarmKeys(MASTER)
    python, drops = XBeeFraming(), Counters()
    c = compiled.Receiver("xbee", drops)
    c.check_tags(list(AuthPolicy).index(auth), lambda *refused: None)
    for _ in range(20):
        unit = b"".join(api_frame(receive_packet(rng.choice([0x0013A20040A1B2C3, 0x7E]), _xbee_rf(rng, keys)))
                        for _ in range(rng.randint(1, 3)))
        if rng.random() < 0.5:
            heard = python.feed(unit)
            assert (c.feed(unit), c.sender if heard else None) == (heard, python.sender_of(unit) if heard else None)
        else:
            pairs = python.feed_tagged(unit)
            got = [(msg, None if proof is None else Tagged(msg, *proof)) for msg, proof in c.feed_tagged(unit)]
            assert got == (pairs if auth is not AuthPolicy.OFF else [(msg, None) for msg, _ in pairs])
    assert drops == python.drops


# -- the same on real devices: ptys and python-can buses, tagged units written straight from C ----------------------

DEVICE_LINKS = SIGNED_LINKS[:3]  # cobs8 on ptys, CAN FD on a python-can bus (an XBee module is tests/xbee's)

def _far_end_bytes(fd: int) -> bytes:
    """What a pty's far end holds now."""
    got = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            return got
        got += chunk


@contextmanager
def _device_node(compiled: bool, refused: list[tuple[str, Message, str]]) -> Iterator[tuple[Node, list[Any]]]:
    """A Node with the swarm key over DEVICE_LINKS on real devices (cobs8 on ptys, CAN FD on a python-can virtual
    bus), its links open and its loop not started (the test hands it units); with each device's far end."""
    fds: list[int] = []
    far: list[Any] = []
    links = []
    try:
        for name, kind, policy in DEVICE_LINKS:
            if kind == "canfd":
                channel = f"tags-{os.getpid()}-{compiled}-{name}"
                spec = f"can:virtual:{channel}?fd=1"
                far.append(can.Bus(interface="virtual", channel=channel, fd=True))
            else:
                master, slave = os.openpty()
                fds += [master, slave]
                for fd in (master, slave):
                    tty.setraw(fd)
                os.set_blocking(master, False)
                spec = f"serial:{os.ttyname(slave)}?framing=cobs8"
                far.append(master)
            links.append(parse(spec).build(name, robot_id=9))
            links[-1].auth = policy
        with pytest.MonkeyPatch.context() as patch:
            if not compiled:
                patch.setattr(assembly_module, "compiled_for", lambda relays, links: None)
            node = Node(links, 9, period=1.0, budget=None, swarm_keys=SwarmKeys(MASTER))
        assert (node._delivery.path is not None) == compiled
        node.listen(refused=lambda heard, reason: refused.append((heard.link, heard.message, reason)))
        for link in links:
            link.open()
        yield node, far
    finally:
        for link in links:
            link.close()
        for end in far:
            if isinstance(end, can.BusABC):
                end.shutdown()
        for fd in fds:
            os.close(fd)


def _received(far: list[Any], into: list[list[Any]]) -> None:
    """What each far end got since the last call, added to `into`: a pty's bytes (one bytes object, the stream so
    far), a bus's frames as (ID, data)."""
    for end, got in zip(far, into, strict=True):
        if isinstance(end, can.BusABC):
            got.extend((f.arbitration_id, bytes(f.data)) for f in iter(partial(end.recv, 0), None))
        else:
            got[:] = [b"".join([*got, _far_end_bytes(end)])]


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**32), steps=st.integers(20, 120))
def test_tagged_units_written_straight_to_ptys_and_buses_equal_the_python_nodes(compiled: ModuleType, seed: int,
                                                                                steps: int) -> None:
    """The same streams through real ptys and a python-can bus: the compiled Node's outlets write each batch (its
    records, the untagged ones, what a link that requires tags holds back) to the device themselves, its writers
    never handed a unit, and every device's far end gets the bytes and frames the Python Node's writers send."""
    keys = SwarmKeys(MASTER)
    told: tuple[list[tuple[str, Message, str]], list[tuple[str, Message, str]]] = ([], [])
    handed: list[str] = []
    with _device_node(False, told[0]) as (pure, pure_far), _device_node(True, told[1]) as (c, c_far):
        nodes, fars = (pure, c), (pure_far, c_far)
        for outlet in c.outlets:  # the writer is Python: a unit handed to it is a wake-up the C write should spare
            outlet.writer.submit = lambda units, count, name=outlet.link.name: handed.append(name)  # type: ignore
        got: tuple[list[list[Any]], list[list[Any]]] = ([[] for _ in DEVICE_LINKS], [[] for _ in DEVICE_LINKS])
        for step in (step for step in _stream(seed, keys, steps) if step[0] == "put" or step[1] < len(DEVICE_LINKS)):
            for node, far, into in zip(nodes, fars, got, strict=True):
                with node._lock:
                    if step[0] == "put":
                        assert node.seat is not None
                        node.seat.put(step[1], step[2])
                        node._outbound.spread(1.0)
                    else:
                        units = _units(random.Random(step[2]), SIGNED_LINKS[step[1]][1], step[3])
                        path = node._delivery.path
                        if path is None or not path.deliver(step[1], 1_700_000_000.0, units, 1.0):
                            node._delivery.arrive(step[1], 1_700_000_000.0, units)
                            node._outbound.spread(1.0, 1 << step[1])
                _received(far, into)
            assert c.stats() == pure.stats(), step
            assert c.engine is not None and pure.engine is not None
            assert list(c.engine.entries()) == list(pure.engine.entries()), step
            assert told[1] == told[0], step
        pure_got, c_got = got
        deadline = time.monotonic() + 5  # a pty's far end may see the last bytes a moment after the write
        while c_got != pure_got and time.monotonic() < deadline:
            for far, into in zip(fars, got, strict=True):
                _received(far, into)
            time.sleep(0.01)
    assert handed == []
    assert c_got == pure_got
    radio = make_serial_framing("cobs8").feed_tagged(c_got[0][0])  # a link that requires tags: every one tagged
    assert all(record is not None and keys.verify(record) for _, record in radio)


def test_an_xbee_encoder_takes_every_batch_size_the_framing_asks_and_no_more(compiled: ModuleType) -> None:
    """The framing's records a batch (its module's NP) reach the shared Encoder, up to the most a frame's data hold;
    one more is refused by name, never written past the Encoder's buffer."""
    framing, encoder = XBeeFraming(), compiled.Encoder("xbee")
    framing.share_sending(encoder)
    for np, records in ((20, 1), (41, 2), (61, 3), (256, 12), (5000, MAX_RECORDS_PER_FRAME)):
        framing.use_module(ModuleInfo(max_payload=np))
        assert encoder.records_per_frame == records
    with pytest.raises(ValueError, match=f"1..{MAX_RECORDS_PER_FRAME} records"):
        encoder.records_per_frame = MAX_RECORDS_PER_FRAME + 1
