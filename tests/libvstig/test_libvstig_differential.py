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
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.engine import ConflictResolver, higher_robot_wins, larger_value_wins, sum_merge
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway.guard import Guard
from vstig_hw.outqueue import OutQueue

EXAMPLES = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# Few keys and timestamps, mostly, so that messages meet: stale, same, conflicts, the wrap, the half-way case.
keys = st.one_of(st.integers(0, 2), st.integers(0, 2), st.just(0x7FFF), st.integers(0, 0x7FFF))
timestamps = st.one_of(st.integers(1, 3), st.integers(1, 3),
                       st.sampled_from([0, 0x7FFF, 0x8000, 0x8001, 0xFFFE, 0xFFFF]), st.integers(0, 0xFFFF))
robots = st.sampled_from([0, 1, 2, 3])
values = st.sampled_from([0, 1, 7, 0xFFFF]) | st.integers(0, 0xFFFF)
messages = st.builds(Message, st.sampled_from(Op), keys, values, timestamps, robots)


def _merge_for_the_lower_robot(key: int, local: Entry, remote: Entry) -> Entry:
    """A merge named for the lower writer (a bad rule, but a legal answer)."""
    return Entry(local.value ^ remote.value, local.timestamp, min(local.robot, remote.robot))


def _sometimes_wrong(key: int, local: Entry, remote: Entry) -> Entry | None:
    """Keeps an entry, merges for itself, names a third robot, or returns nothing, by the values."""
    choice = (local.value + remote.value) % 4
    if choice == 0:
        return local
    if choice == 1:
        return Entry(local.value + 1 & 0xFFFF, 0, 2)
    if choice == 2:
        return Entry(9, local.timestamp, 77)
    return None


# (the Python rule, whether the C engine runs its own twin of it)
RULES: list[tuple[ConflictResolver, bool]] = [
    (higher_robot_wins, True), (larger_value_wins, True), (sum_merge, True), (higher_robot_wins, False),
    (_merge_for_the_lower_robot, False), (_sometimes_wrong, False),  # type: ignore[list-item]
]

operations = st.one_of(
    st.tuples(st.just("put"), keys, values),
    st.tuples(st.just("get"), keys),
    st.tuples(st.just("receive"), messages),
    st.tuples(st.just("batch"), st.lists(messages, max_size=5)),
    st.tuples(st.just("drain"), st.none() | st.integers(0, 3)),
)


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
@given(robot=robots, rule=st.sampled_from(RULES), ops=st.lists(operations, max_size=60))
def test_engine_equals_the_python_engine(lib: Lib, robot: int, rule: tuple[ConflictResolver, bool],
                                         ops: list[tuple[object, ...]]) -> None:
    resolver, c_rule = rule
    if any(o[0] == "batch" and resolver is _sometimes_wrong for o in ops):
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
@given(ops=st.lists(st.tuples(st.just("push"), messages) | st.tuples(st.just("drain"), st.none() | st.integers(0, 4)),
                    max_size=80))
def test_outgoing_queue_equals_the_python_queue(lib: Lib, ops: list[tuple[str, object]]) -> None:
    python, c = OutQueue(), COutQueue.on(lib)()
    for name, arg in ops:
        if name == "push":
            assert c.push(arg) == python.push(arg), arg  # type: ignore[arg-type]
        else:
            assert c.drain(arg) == python.drain(arg)  # type: ignore[arg-type]
        assert len(c) == len(python)
    assert c.drain() == python.drain()


UNITS = 1024  # guard time units a second: every time is k/1024 s, exact in a float


# A key's timestamps climb from the last one by a few steps, sometimes far, sometimes back.
climbs = st.one_of(st.integers(0, 4), st.integers(-3, 300), st.sampled_from([255, 256, 0x8000]), st.integers(0, 0xFFFF))


@EXAMPLES
@example(max_jump=2, learn=None, traffic=[(Op.PUT, 0, 5, 1, 0)] + [(Op.PUT, 0, 2, 1, 0)] * 3)  # a budget spent to 0
@given(max_jump=st.sampled_from([1, 2, 3, 255, 32767]) | st.integers(1, 300),
       learn=st.none() | st.integers(0, 4 * UNITS),
       traffic=st.lists(st.tuples(st.sampled_from(Op), st.integers(0, 2), climbs, robots,
                                  st.one_of(st.just(0), st.integers(0, 64), st.integers(-50, 3 * UNITS))), max_size=80))
def test_jump_guard_equals_the_python_guard(lib: Lib, max_jump: int, learn: int | None,
                                            traffic: list[tuple[Op, int, int, int, int]]) -> None:
    python = Guard(max_jump=max_jump, learn=None if learn is None else learn / UNITS)
    c = CGuard(lib, max_jump, UNITS, learn)
    assert c.status == 0
    now = 1_000_000  # units; steps back now and then, as a clock may
    last = [0, 0, 0]
    for op, key, climb, robot, step in traffic:
        now += step
        last[key] = (last[key] + climb) & 0xFFFF
        msg = Message(op, key, climb & 0xFFFF, last[key], robot)
        refused = python.check("radio", None, msg, now / UNITS) == "drop_jump"
        assert c.check(msg, now) == refused, (msg, now)
    for key in range(3):
        assert c.view(key) == python._view.get(key)


def _noisy(rng: random.Random, frames: list[bytes]) -> bytes:
    out = bytearray()
    for frame in frames:
        roll = rng.random()
        if roll < 0.15:
            frame = bytes(b ^ (1 << rng.randrange(8)) if i == rng.randrange(len(frame)) else b
                          for i, b in enumerate(frame))
        elif roll < 0.25:
            frame = frame[: rng.randrange(1, len(frame))]
        elif roll < 0.3:
            out += rng.randbytes(rng.randrange(1, 90))
        elif roll < 0.35:
            out += b"\x00" * rng.randrange(1, 3)
        out += frame
    return bytes(out)


@EXAMPLES
@given(framing=st.sampled_from(["cobs8", "epuck4", "kilobot"]), seed=st.integers(0, 2**32),
       sent=st.lists(messages, min_size=1, max_size=12), most=st.integers(1, 3))
def test_serial_receivers_over_buffers_equal_the_python_framings(lib: Lib, framing: str, seed: int,
                                                                 sent: list[Message], most: int) -> None:
    rng = random.Random(seed)
    python = make_serial_framing(framing)
    others = make_serial_framing("kilobot" if framing == "cobs8" else "cobs8")
    frames = [unit for m in sent for unit in python.encode(m)] + [u for m in sent[:2] for u in others.encode(m)]
    stream = _noisy(rng, frames)
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


schemes = st.sampled_from([(False, None, 0), (False, 0x200, 0), (True, None, 0), (True, 0x02000000, 255),
                           (True, None, 3)])


@st.composite
def can_frames(draw: st.DrawFn) -> can.Message:
    extended = draw(st.booleans())
    fd = draw(st.booleans())
    length = draw(st.sampled_from([8, 16, 24, 32, 48, 64, 0, 5, 12, 40, 56]) if fd else st.sampled_from([8, 8, 0, 7]))
    near = [0x605, 0x705, 0x2FF, 0x105, 0x7FF] if not extended else [0x18000005, 0x18010005, 0x03FEFFFF, 0x18060005]
    can_id = draw(st.sampled_from(near) | st.integers(0, 0x1FFFFFFF if extended else 0x7FF))
    data = bytearray(draw(st.binary(min_size=length, max_size=length)))
    op = can_id >> (16 if extended else 8) & 1
    for at in range(0, length - 7, 8):  # mostly the ID's op, so that frames get through
        data[at] = data[at] & 0x7F | (op if draw(st.integers(0, 5)) else 1 - op) << 7
    return can.Message(arbitration_id=can_id, is_extended_id=extended, is_fd=fd, bitrate_switch=fd,
                       is_remote_frame=draw(st.integers(0, 9)) == 0 and not fd,
                       is_error_frame=draw(st.integers(0, 19)) == 0, data=bytes(data))


@EXAMPLES
@given(scheme=schemes, frames=st.lists(can_frames(), max_size=20))
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
@given(scheme=schemes, sender=st.integers(0, 255), fd=st.booleans(), sent=st.lists(messages, max_size=30))
def test_can_encode_equals_the_python_framing(lib: Lib, scheme: tuple[bool, int | None, int], sender: int,
                                              fd: bool, sent: list[Message]) -> None:
    extended, base, stigmergy = scheme
    python = CanFraming(CanIdScheme(extended=extended, base=base, stigmergy=stigmergy), sender=sender, fd=fd)
    c = CCan(lib, extended, base, stigmergy, sender, fd=fd)
    assert c.status == 0
    want = [(f.arbitration_id, f.is_extended_id, f.is_fd, f.bitrate_switch, bytes(f.data))
            for f in python.encode_batch(sent)]
    assert [(f.id, bool(f.extended), bool(f.fd), bool(f.brs), bytes(f.data[:f.len])) for f in c.encode(sent)] == want
