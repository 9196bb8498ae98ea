"""Each compiled type against the Python class it stands in for, on random traffic (hypothesis): the same calls, in
the same order, give the same results, tables, queues, counters and drops.

Engine vs Stigmergy (put, get, receive, drain; the ready-made rules run as their C twins, other rules are called back
from C, refused winners raise alike); JumpGuard vs a Guard of max_jump and learn (times in 1/1024 s, which floats hold
exactly); Receiver vs the serial and CAN framings over noisy streams cut anywhere; Encoder vs the framings' units.
The engine tests that pin each difference from Buzz run again with the compiled Engine standing in.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from types import ModuleType
from typing import Any

import can
import pytest
from buzz_rows import ENGINE_TESTS, with_twins
from hypothesis import given
from hypothesis import strategies as st
from traffic import (
    EXAMPLES,
    GUARD_UNITS,
    RULES,
    SERIAL_FRAMINGS,
    can_frames,
    can_schemes,
    engine_calls,
    guard_traffic,
    guarded,
    learns,
    max_jumps,
    messages,
    noisy,
    robots,
    xbee_stream,
)

from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.counters import Counters
from vstig_hw.engine import ConflictResolver
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway.guard import Guard


def _call(engine: Any, call: tuple[Any, ...]) -> object:
    """One engine call's result, or the type and text of what it raised."""
    name, *args = call
    try:
        if name == "batch":
            return [engine.receive(m) for m in args[0]]
        return getattr(engine, name)(*args)
    except (TypeError, ValueError) as error:
        return type(error), str(error)


def _raising_rule(key: int, local: Entry, remote: Entry) -> Entry:
    if local.value == remote.value:
        raise KeyError(key)
    return remote


@EXAMPLES
@given(robot=robots, rule=st.sampled_from([*RULES, (_raising_rule, False)]), lost_raises=st.booleans(),
       calls=st.lists(engine_calls, max_size=60))
def test_engine_equals_stigmergy(compiled: ModuleType, robot: int, rule: tuple[ConflictResolver, bool],
                                 lost_raises: bool, calls: list[tuple[Any, ...]]) -> None:
    resolver, _ = rule
    lost: dict[str, list[tuple[int, Entry]]] = {"python": [], "c": []}

    def on_lost(side: str) -> Callable[[int, Entry], None]:
        def report(key: int, entry: Entry) -> None:
            lost[side].append((key, entry))
            if lost_raises:
                raise OSError(key)
        return report

    python = Stigmergy(robot, resolver, on_lost("python"))
    c = compiled.Engine(robot, resolver, on_lost("c"))
    for call in calls:
        try:
            want = _call(python, call)
        except (KeyError, OSError) as error:
            with pytest.raises(type(error)):
                _call(c, call)
        else:
            assert _call(c, call) == want, call
        assert lost["c"] == lost["python"]
        assert list(c.entries()) == list(python.entries())
    assert c.counts == python.counts
    assert (c.size(), c.pending(), c.robot_id) == (python.size(), python.pending(), python.robot_id)
    assert [c.has(k) for k in (0, 1, 2, -1, "x", 0x7FFF)] == [python.has(k) for k in (0, 1, 2, -1, "x", 0x7FFF)]
    assert c.drain() == python.drain()


def test_engine_refuses_what_stigmergy_refuses(compiled: ModuleType) -> None:
    for args in [(-1,), (0x10000,), (True,), ("7",)]:
        with pytest.raises(ValueError) as python:
            Stigmergy(*args)
        with pytest.raises(ValueError) as c:
            compiled.Engine(*args)
        assert str(c.value) == str(python.value)
    python, c = Stigmergy(1), compiled.Engine(1)
    for name, args in [("put", (0x8000, 1)), ("put", (1, -1)), ("put", (1.0, 1)), ("get", (None,)),
                       ("drain", (-1,))]:
        python.put(5, 5)
        c.put(5, 5)
        assert _call(c, (name, *args)) == _call(python, (name, *args))


def test_the_rule_can_change_and_the_twins_follow(compiled: ModuleType) -> None:
    """Swarm sets `onconflict` after building the engine, and a ready-made rule set later runs as its C twin."""
    from vstig_hw.engine import larger_value_wins

    python, c = Stigmergy(1), compiled.Engine(1)
    for engine in (python, c):
        engine.onconflict = larger_value_wins
        engine.receive(Message(Op.PUT, 1, 9, 1, 2))
        engine.receive(Message(Op.PUT, 1, 3, 1, 3))
    assert c.onconflict is larger_value_wins
    assert c.entry(1) == python.entry(1) == Entry(9, 1, 2)


@pytest.mark.parametrize(("path", "name"), ENGINE_TESTS, ids=[name for _, name in ENGINE_TESTS])
def test_each_difference_from_buzz_holds_for_the_compiled_engine(compiled: ModuleType, path: str, name: str) -> None:
    module = with_twins(path, "native_twin_", Stigmergy=compiled.Engine)
    assert getattr(module, "Stigmergy", compiled.Engine) is compiled.Engine
    test: Callable[[], None] = getattr(module, name)
    test()


@EXAMPLES
@given(max_jump=max_jumps, learn=learns, traffic=guard_traffic, batch=st.integers(1, 4))
def test_jump_guard_equals_guard(compiled: ModuleType, max_jump: int, learn: int | None,
                                 traffic: list[tuple[Op, int, int, int, int]], batch: int) -> None:
    seconds = None if learn is None else learn / GUARD_UNITS
    python, c = Guard(max_jump=max_jump, learn=seconds), compiled.JumpGuard(max_jump, seconds)
    counted: dict[str, Counters] = {"python": Counters(), "c": Counters()}
    heard = guarded(traffic)
    for at in range(0, len(heard), batch):  # filter a few at a time, as a link's unit carries them
        chunk = heard[at:at + batch]
        now = chunk[0][1] / GUARD_UNITS
        batch_messages = [msg for msg, _ in chunk]
        want = python.filter("radio", None, batch_messages, now, counted["python"])
        assert c.filter("radio", None, batch_messages, now, counted["c"]) == want
    assert counted["c"] == counted["python"]
    for key in range(3):
        assert c.view(key) == python._view.get(key)
    assert (c.read_only("radio"), c.confines, c.confined_to(Message(Op.PUT, 1, 1, 1, 1)), c.warnings) == \
        (python.read_only("radio"), python.confines, python.confined_to(Message(Op.PUT, 1, 1, 1, 1)), [])


@EXAMPLES
@given(framing=st.sampled_from(SERIAL_FRAMINGS), seed=st.integers(0, 2**32), sent=st.lists(messages, min_size=1,
                                                                                         max_size=12))
def test_serial_receiver_equals_the_framing(compiled: ModuleType, framing: str, seed: int,
                                            sent: list[Message]) -> None:
    rng = random.Random(seed)
    python = make_serial_framing(framing)
    others = make_serial_framing("kilobot" if framing == "cobs8" else "cobs8")
    stream = noisy(rng, [unit for m in sent for unit in python.encode(m)] +
                   [unit for m in sent[:2] for unit in others.encode(m)])
    drops = Counters()
    c = compiled.Receiver(framing, drops)
    at = 0
    while at < len(stream):
        cut = rng.randrange(1, 24)
        chunk, at = stream[at:at + cut], at + cut
        assert c.feed(chunk) == python.feed(chunk)
        if rng.random() < 0.2:
            c.tick()
            python.tick()
        if rng.random() < 0.05:
            c.reset()
            python.reset()
    assert drops == python.drops


@EXAMPLES
@given(scheme=can_schemes, frames=st.lists(can_frames(), max_size=20))
def test_can_receiver_equals_the_framing(compiled: ModuleType, scheme: tuple[bool, int | None, int],
                                         frames: list[can.Message]) -> None:
    extended, base, stigmergy = scheme
    python = CanFraming(CanIdScheme(extended=extended, base=base, stigmergy=stigmergy), sender=0)
    drops = Counters()
    c = compiled.Receiver("can", drops, extended=extended, base=base, stigmergy=stigmergy)
    for frame in frames:
        assert c.feed(frame) == python.feed(frame)
    assert drops == python.drops


@EXAMPLES
@given(framing=st.sampled_from(SERIAL_FRAMINGS), sent=st.lists(messages, max_size=20))
def test_serial_encoder_equals_the_link_units(compiled: ModuleType, framing: str, sent: list[Message]) -> None:
    """A byte stream's units are joined into one write (Link.units_of)."""
    units = [unit for msg in sent for unit in make_serial_framing(framing).encode(msg)]
    assert compiled.Encoder(framing).encode_batch(sent) == ([b"".join(units)] if units else [])


@EXAMPLES
@given(scheme=can_schemes, sender=st.integers(0, 255), fd=st.booleans(), brs=st.booleans(),
       sent=st.lists(messages, max_size=30))
def test_can_encoder_equals_the_framing(compiled: ModuleType, scheme: tuple[bool, int | None, int], sender: int,
                                        fd: bool, brs: bool, sent: list[Message]) -> None:
    extended, base, stigmergy = scheme
    python = CanFraming(CanIdScheme(extended=extended, base=base, stigmergy=stigmergy), sender=sender, fd=fd,
                        bitrate_switch=brs)
    c = compiled.Encoder("can", extended=extended, base=base, stigmergy=stigmergy, sender=sender, fd=fd, brs=brs,
                         frame_type=can.Message)

    def fields(frames: list[can.Message]) -> list[tuple[object, ...]]:
        """Every slot python-can declares, with its type (the compiled units are copies of one can.Message)."""
        return [tuple((name, type(getattr(f, name)), getattr(f, name)) for name in can.Message.__slots__
                      if name != "__weakref__") for f in frames]

    made = c.encode_batch(sent)
    assert fields(made) == fields(python.encode_batch(sent))
    assert len({id(f.data) for f in made}) == len(made)  # each its own data: a copy shares nothing mutable


def _xbee_pair(compiled: ModuleType, api: int) -> tuple[Any, Any, Counters]:
    """(the Python framing, its compiled Receiver counting into its own Counters, those Counters)."""
    python = make_serial_framing("xbee-api2" if api == 2 else "xbee")
    drops = Counters()
    return python, compiled.Receiver("xbee", drops, escaped=api == 2), drops


def _xbee_units(rng: random.Random, stream: bytes, api: int) -> list[bytes]:
    """Units as the transport cuts them (whole frames, reports kept back), and as a hand-made capture may hold them
    (any bytes: the framing reads every unit whole)."""
    from vstig_hw.transports.xbee import XBeeTransport

    transport = XBeeTransport("unopened", api=api)  # never opened: its cutting alone
    cut = transport.cut(stream) + transport.quiet()
    at, chunks = 0, []
    while at < len(stream):
        step = rng.randrange(1, 80)
        chunks.append(stream[at:at + step])
        at += step
    return cut + chunks


@EXAMPLES
@given(api=st.sampled_from([1, 2]), seed=st.integers(0, 2**32))
def test_xbee_receiver_equals_the_framing(compiled: ModuleType, api: int, seed: int) -> None:
    """Hostile streams (tests/traffic.py), in whole frames and in random pieces: the same messages, the same sender
    (the 64-bit source the guard and sniff see) and the same drops."""
    rng = random.Random(seed)
    python, c, drops = _xbee_pair(compiled, api)
    for unit in _xbee_units(rng, xbee_stream(rng, api == 2), api):
        heard = python.feed(unit)
        assert (c.feed(unit), c.sender if heard else None) == (heard, python.sender_of(unit) if heard else None)
        if rng.random() < 0.1:
            c.reset()
            python.reset()
    assert drops == python.drops


@pytest.mark.parametrize("api", [1, 2])
def test_xbee_receiver_split_at_every_byte_equals_the_framing(compiled: ModuleType, api: int) -> None:
    """A hostile stream cut in two at every byte: each half a unit, as the framing reads it."""
    rng = random.Random(api)
    for _ in range(4):
        stream = xbee_stream(rng, api == 2, frames=6)
        for cut in range(len(stream) + 1):
            python, c, drops = _xbee_pair(compiled, api)
            for unit in (stream[:cut], stream[cut:]):
                assert c.feed(unit) == python.feed(unit)
            assert drops == python.drops, cut


@EXAMPLES
@given(api=st.sampled_from([1, 2]), dest=st.sampled_from([0xFFFF, 0x0013A20040A1B2C3, 0x7D7E1113]),
       np=st.sampled_from([None, 5, 64, 73, 256, 1000]),
       batches=st.lists(st.tuples(st.booleans(), st.lists(messages, max_size=70)), max_size=8))
def test_xbee_encoder_equals_the_framing(compiled: ModuleType, api: int, dest: int, np: int | None,
                                         batches: list[tuple[bool, list[Message]]]) -> None:
    """The same Transmit Requests (frame ids after ticks, NP, escapes, the destination), and once the framing
    shares the Encoder's fields, frames from either side go on one count of frame ids."""
    from vstig_hw.framing.xbee import ModuleInfo, XBeeApi2Framing, XBeeFraming

    kind = XBeeApi2Framing if api == 2 else XBeeFraming
    python, sharing = kind(dest), kind(dest)
    c = compiled.Encoder("xbee", escaped=api == 2, dest=dest)
    for framing in (python, sharing):
        framing.use_module(ModuleInfo(max_payload=np))
    sharing.share_sending(c)
    for i, (tick, sent) in enumerate(batches):
        if tick:
            python.tick()
            sharing.tick()
        want = b"".join(python.encode_batch(sent))
        got = b"".join(sharing.encode_batch(sent)) if i % 2 else b"".join(c.encode_batch(sent))
        assert got == want
    assert (c.frame_id, bool(c.report), c.per_frame) == (python.sending.frame_id, python.sending.report,
                                                         python.per_frame)
