"""Random traffic for the differential tests (hypothesis): libvstig through ctypes (tests/libvstig) and the
compiled data path (tests/native) each meet the Python reference on the same kinds of calls and streams."""

from __future__ import annotations

import random

import can
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from vstig_hw import Entry, Message, Op
from vstig_hw.engine import ConflictResolver, higher_robot_wins, larger_value_wins, sum_merge

EXAMPLES = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# Few keys and timestamps, mostly, so that messages meet: stale, same, conflicts, the wrap, the half-way case.
keys = st.one_of(st.integers(0, 2), st.integers(0, 2), st.just(0x7FFF), st.integers(0, 0x7FFF))
timestamps = st.one_of(st.integers(1, 3), st.integers(1, 3),
                       st.sampled_from([0, 0x7FFF, 0x8000, 0x8001, 0xFFFE, 0xFFFF]), st.integers(0, 0xFFFF))
robots = st.sampled_from([0, 1, 2, 3])
values = st.sampled_from([0, 1, 7, 0xFFFF]) | st.integers(0, 0xFFFF)
messages = st.builds(Message, st.sampled_from(Op), keys, values, timestamps, robots)


def merge_for_the_lower_robot(key: int, local: Entry, remote: Entry) -> Entry:
    """A merge named for the lower writer (a bad rule, but a legal answer)."""
    return Entry(local.value ^ remote.value, local.timestamp, min(local.robot, remote.robot))


def sometimes_wrong(key: int, local: Entry, remote: Entry) -> Entry | None:
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
    (merge_for_the_lower_robot, False), (sometimes_wrong, False),  # type: ignore[list-item]
]

engine_calls = st.one_of(
    st.tuples(st.just("put"), keys, values),
    st.tuples(st.just("get"), keys),
    st.tuples(st.just("receive"), messages),
    st.tuples(st.just("batch"), st.lists(messages, max_size=5)),
    st.tuples(st.just("drain"), st.none() | st.integers(0, 3)),
)

queue_calls = st.lists(st.tuples(st.just("push"), messages)
                       | st.tuples(st.just("drain"), st.none() | st.integers(0, 4)), max_size=80)

GUARD_UNITS = 1024  # guard time units a second: every time is k/1024 s, exact in a float

# A key's timestamps climb from the last one by a few steps, sometimes far, sometimes back.
climbs = st.one_of(st.integers(0, 4), st.integers(-3, 300), st.sampled_from([255, 256, 0x8000]), st.integers(0, 0xFFFF))
guard_traffic = st.lists(st.tuples(st.sampled_from(Op), st.integers(0, 2), climbs, robots,
                                   st.one_of(st.just(0), st.integers(0, 64), st.integers(-50, 3 * GUARD_UNITS))),
                         max_size=80)
max_jumps = st.sampled_from([1, 2, 3, 255, 32767]) | st.integers(1, 300)
learns = st.none() | st.integers(0, 4 * GUARD_UNITS)  # in units


def guarded(traffic: list[tuple[Op, int, int, int, int]]) -> list[tuple[Message, int]]:
    """`guard_traffic` as (message, time in units): each key's timestamp climbs, the clock moves (back, now and
    then)."""
    now = 1_000_000
    last = [0, 0, 0]
    out = []
    for op, key, climb, robot, step in traffic:
        now += step
        last[key] = (last[key] + climb) & 0xFFFF
        out.append((Message(op, key, climb & 0xFFFF, last[key], robot), now))
    return out


def noisy(rng: random.Random, frames: list[bytes]) -> bytes:
    """Frames with some corrupted, cut short, or with garbage or idle bytes between them."""
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


SERIAL_FRAMINGS = ("cobs8", "epuck4", "kilobot")

# (extended, base, stigmergy)
can_schemes = st.sampled_from([(False, None, 0), (False, 0x200, 0), (True, None, 0), (True, 0x02000000, 255),
                               (True, None, 3)])


@st.composite
def can_frames(draw: st.DrawFn) -> can.Message:
    """CAN frames near the default schemes' IDs, mostly of the ID's op: error, remote and odd-length frames too."""
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


def xbee_stream(rng: random.Random, escaped: bool, frames: int = 12,
                types: tuple[int, ...] = (0x95, 0x10, 0x90)) -> bytes:
    """What a module hands its host, hostile: Receive Packets from a few modules (one to many messages, the
    bytes a mode-2 module escapes among them), the module's own reports, frame types a link does not use,
    RF data that are not whole messages (frame `types`), lengths of 0 and above the bound, then `noisy`'s
    corruption and cuts, escapes gone wrong and stray 0x7E/0x7D/0x11/0x13 bytes."""
    from vstig_hw.framing.xbee import api_frame, receive_packet

    special = (0x7E, 0x7D, 0x11, 0x13)
    units = []
    for _ in range(frames):
        roll = rng.random()
        if roll < 0.6:
            rf = b"".join(bytes(rng.choice((rng.choice(special), rng.randrange(256))) for _ in range(8))
                          for _ in range(rng.choice((1, 1, 2, 8, 62))))
            data = receive_packet(rng.choice((0x0013A20040A1B2C3, 0x0013A2004000007E, 0x7D11)), rf)
        elif roll < 0.7:
            data = bytes((rng.choice((0x8B, 0x8A, 0x88)),)) + rng.randbytes(rng.randrange(1, 8))  # reports
        elif roll < 0.8:
            data = bytes((rng.choice(types),)) + rng.randbytes(rng.randrange(0, 30))
        else:
            units.append(b"\x7e" + rng.choice((b"\x00\x00", b"\x02\x01", b"\x7d\x31")) + rng.randbytes(4))
            continue
        units.append(api_frame(data, escaped))
    stream = bytearray(noisy(rng, units))
    for _ in range(rng.randrange(4)):  # a stray special byte, or a broken escape
        stray = rng.choice((b"\x7e", b"\x7d", b"\x11", b"\x13", b"\x7d\x00", b"\x7d\x5e"))
        at = rng.randrange(len(stream) + 1)
        stream[at:at] = stray
    return bytes(stream)
