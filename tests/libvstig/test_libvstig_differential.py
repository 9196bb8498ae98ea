"""libvstig against the Python reference on random traffic (hypothesis): the same calls, in the same order, must
give the same results, tables, queues, counters and drops.

Engine (put, get, receive one or a batch, drain, with the C rules and with Python rules called back from C,
merges and refused winners included), outgoing queue (winner replaces loser, places in line), the jump guard
(times in 1/1024 s, which a float holds exactly, so the budgets compare exactly), the serial framings over
buffers cut anywhere, and the CAN framing both ways.
"""

from __future__ import annotations

import random

import can
from clib import CCan, CGuard, COutQueue, CSerial, CStigmergy, Lib, frame_of
from hypothesis import example, given
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
    queue_calls,
    robots,
    sometimes_wrong,
)

from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.engine import ConflictResolver
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway.guard import Guard
from vstig_hw.outqueue import OutQueue


def _do(engine: Stigmergy | CStigmergy, operation: tuple[object, ...]) -> object:
    name = operation[0]
    try:
        if name == "put":
            return engine.put(*operation[1:])  # type: ignore[arg-type]
        if name == "get":
            return engine.get(*operation[1:])  # type: ignore[arg-type]
        if name == "receive":
            return engine.receive(*operation[1:])  # type: ignore[arg-type]
        if name == "batch":
            if isinstance(engine, CStigmergy):
                return engine.receive_many(*operation[1:])  # type: ignore[arg-type]
            return [engine.receive(m) for m in operation[1]]  # type: ignore[attr-defined]
        return engine.drain(*operation[1:])  # type: ignore[arg-type]
    except (TypeError, ValueError) as error:
        return type(error)


@EXAMPLES
@given(robot=robots, rule=st.sampled_from(RULES), ops=st.lists(engine_calls, max_size=60))
def test_engine_equals_the_python_engine(lib: Lib, robot: int, rule: tuple[ConflictResolver, bool],
                                         ops: list[tuple[object, ...]]) -> None:
    resolver, c_rule = rule
    if any(o[0] == "batch" and resolver is sometimes_wrong for o in ops):
        ops = [o for o in ops if o[0] != "batch"]  # the Python engine stops a batch at a raise; C goes on
    lost_py: list[tuple[int, Entry]] = []
    lost_c: list[tuple[int, Entry]] = []
    python = Stigmergy(robot, resolver, lambda key, entry: lost_py.append((key, entry)))
    c = CStigmergy.on(lib)(robot, resolver, lambda key, entry: lost_c.append((key, entry)), c_rule=c_rule)
    for operation in ops:
        assert _do(c, operation) == _do(python, operation), operation
        assert lost_c == lost_py
    assert list(c.entries()) == sorted(python.entries())
    assert c.counts == python.counts
    assert c.size() == python.size()
    assert c.pending() == python.pending()
    assert c.drain() == python.drain()


@EXAMPLES
@given(ops=queue_calls)
def test_outgoing_queue_equals_the_python_queue(lib: Lib, ops: list[tuple[str, object]]) -> None:
    python, c = OutQueue(), COutQueue.on(lib)()
    for name, arg in ops:
        if name == "push":
            assert c.push(arg) == python.push(arg), arg  # type: ignore[arg-type]
        else:
            assert c.drain(arg) == python.drain(arg)  # type: ignore[arg-type]
        assert len(c) == len(python)
    assert c.drain() == python.drain()


@EXAMPLES
@example(max_jump=2, learn=None, traffic=[(Op.PUT, 0, 5, 1, 0)] + [(Op.PUT, 0, 2, 1, 0)] * 3)  # a budget spent to 0
@given(max_jump=max_jumps, learn=learns, traffic=guard_traffic)
def test_jump_guard_equals_the_python_guard(lib: Lib, max_jump: int, learn: int | None,
                                            traffic: list[tuple[Op, int, int, int, int]]) -> None:
    python = Guard(max_jump=max_jump, learn=None if learn is None else learn / GUARD_UNITS)
    c = CGuard(lib, max_jump, GUARD_UNITS, learn)
    assert c.status == 0
    for msg, now in guarded(traffic):  # now in units; it steps back now and then, as a clock may
        refused = python.check("radio", None, msg, now / GUARD_UNITS) == "drop_jump"
        assert c.check(msg, now) == refused, (msg, now)
    for key in range(3):
        assert c.view(key) == python._view.get(key)


@EXAMPLES
@given(framing=st.sampled_from(SERIAL_FRAMINGS), seed=st.integers(0, 2**32),
       sent=st.lists(messages, min_size=1, max_size=12), most=st.integers(1, 3))
def test_serial_receivers_over_buffers_equal_the_python_framings(lib: Lib, framing: str, seed: int,
                                                                 sent: list[Message], most: int) -> None:
    rng = random.Random(seed)
    python = make_serial_framing(framing)
    others = make_serial_framing("kilobot" if framing == "cobs8" else "cobs8")
    frames = [unit for m in sent for unit in python.encode(m)] + [u for m in sent[:2] for u in others.encode(m)]
    stream = noisy(rng, frames)
    c = CSerial(lib, {"cobs8": 0, "epuck4": 1, "kilobot": 2}[framing], most=most)
    assert c.status == 0
    at = 0
    while at < len(stream):
        cut = rng.randrange(1, 24)
        chunk, at = stream[at:at + cut], at + cut
        assert c.feed(chunk) == python.feed(chunk)
        if framing == "epuck4" and rng.random() < 0.2:
            c.tick()
            python.tick()
    assert c.drops == +python.drops


@EXAMPLES
@given(scheme=can_schemes, frames=st.lists(can_frames(), max_size=20))
def test_can_receive_equals_the_python_framing(lib: Lib, scheme: tuple[bool, int | None, int],
                                               frames: list[can.Message]) -> None:
    extended, base, stigmergy = scheme
    python = CanFraming(CanIdScheme(extended=extended, base=base, stigmergy=stigmergy), sender=0)
    c = CCan(lib, extended, base, stigmergy, 0)
    assert c.status == 0
    for frame in frames:
        got, sender = c.receive(frame_of(frame.arbitration_id, bytes(frame.data), extended=frame.is_extended_id,
                                         fd=frame.is_fd, rtr=frame.is_remote_frame, error=frame.is_error_frame))
        want = python.feed(frame)
        assert got == want
        if want:
            assert sender == python.sender_of(frame)
    assert c.drops == +python.drops


@EXAMPLES
@given(scheme=can_schemes, sender=st.integers(0, 255), fd=st.booleans(), sent=st.lists(messages, max_size=30))
def test_can_encode_equals_the_python_framing(lib: Lib, scheme: tuple[bool, int | None, int], sender: int,
                                              fd: bool, sent: list[Message]) -> None:
    extended, base, stigmergy = scheme
    python = CanFraming(CanIdScheme(extended=extended, base=base, stigmergy=stigmergy), sender=sender, fd=fd)
    c = CCan(lib, extended, base, stigmergy, sender, fd=fd)
    assert c.status == 0
    want = [(f.arbitration_id, f.is_extended_id, f.is_fd, f.bitrate_switch, bytes(f.data))
            for f in python.encode_batch(sent)]
    assert [(f.id, bool(f.extended), bool(f.fd), bool(f.brs), bytes(f.data[:f.len])) for f in c.encode(sent)] == want
