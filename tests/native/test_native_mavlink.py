"""The compiled mavlink Receiver and Encoder (vstig_hw/_cext/mavlink.c, framing.c) against MavlinkFraming, their
Python reference, on random hostile traffic (hypothesis): frames of ours signed and unsigned, replayed (the same
frame again, an older timestamp), forged (a wrong key, a flipped byte), other messages, MAVLink 1, noise, cut
short. The same units fed to both must give the same messages, the same senders and the same drop counters; the
replay table must forget the same streams (1024 kept) as `Signing` does. What the Encoder sends, pymavlink reads.
"""

from __future__ import annotations

import random
from types import ModuleType
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from vstig_hw.auth import Tagged
from vstig_hw.counters import Counters
from vstig_hw.framing.mavlink import (
    NEW_STREAM_WINDOW,
    STREAMS_KEPT,
    TUNNEL,
    MavlinkFraming,
    MavlinkStreamReader,
    Signing,
    frame,
    signing_timestamp,
    tunnel_payload,
)
from vstig_hw.wire import Message, Op, encode

KEY = bytes(range(32))
FORGED_KEY = bytes(range(1, 33))
T0 = 4_102_444_800.0  # 2100-01-01: a signing clock ahead of the system's, so the Encoder's goes on from it


def _messages(rng: random.Random, n: int) -> list[Message]:
    return [Message(Op(rng.randrange(2)), rng.randrange(32768), rng.randrange(65536), rng.randrange(65536),
                    rng.randrange(65536)) for _ in range(n)]


def _signed_tunnel(rng: random.Random, stamp: int, key: bytes = KEY) -> bytes:
    data = b"".join(map(encode, _messages(rng, rng.randrange(1, 17))))
    return frame(TUNNEL, tunnel_payload(data, rng.choice((0, 0, 4, 9))), seq=rng.randrange(256),
                 sysid=rng.randrange(1, 6), compid=rng.choice((1, 191)), key=key, link_id=rng.randrange(3),
                 timestamp=stamp)


def hostile_units(seed: int, keyed: bool, count: int) -> list[bytes]:
    """Units as a mavlink transport hands them (mostly one frame each, some glued or cut), of every kind."""
    rng = random.Random(seed)
    sender = MavlinkFraming(rng.randrange(1, 256), rng.choice((1, 191)), target=rng.choice((0, 0, 4, 5)),
                            signing=Signing(KEY, clock=lambda: T0) if keyed and rng.random() < 0.8 else None)
    stamp = signing_timestamp(T0)
    units: list[bytes] = []
    for _ in range(count):
        kind = rng.random()
        if kind < 0.27:
            unit = sender.encode_batch(_messages(rng, rng.randrange(1, 17)))[0]
        elif kind < 0.35:  # tagged TUNNELs (SPEC.md 10.5): both take their messages, without the tags
            unit = sender.encode_tagged([Tagged(m, rng.randrange(3), rng.randbytes(8))
                                         for m in _messages(rng, rng.randrange(1, 7))])[0]
        elif kind < 0.55:  # signed streams of several senders, time going forward, back or far back
            stamp += rng.choice((1, 5, 1000, -3, -NEW_STREAM_WINDOW - 10))
            unit = _signed_tunnel(rng, max(stamp, 0), FORGED_KEY if rng.random() < 0.1 else KEY)
        elif kind < 0.62:
            unit = sender.heartbeat()
        elif kind < 0.67:
            unit = bytes([0xFE, 3, 0, 1, 1, 0, 1, 2, 3, 0x11, 0x22])
        elif kind < 0.72 and units:
            unit = units[rng.randrange(len(units))]  # the same frame again: a replay with a key
        elif kind < 0.77:
            unit = frame(TUNNEL, tunnel_payload(b"\x01" * 8, payload_type=rng.choice((1, 0x8000))), seq=1, sysid=2,
                         compid=1)
        else:
            unit = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 30)))
        mangled = bytearray(unit)
        if rng.random() < 0.1 and mangled:  # (a replayed unit may be one cut to nothing)
            mangled[rng.randrange(len(mangled))] ^= 1 << rng.randrange(8)
        if rng.random() < 0.08 and mangled:
            del mangled[rng.randrange(len(mangled)):]
        if rng.random() < 0.05 and units:
            mangled += units[-1]
        units.append(bytes(mangled))
    return units


def _feed_both(compiled: ModuleType, units: list[bytes], keyed: bool) -> None:
    python = MavlinkFraming(4, 191, signing=Signing(KEY) if keyed else None)
    drops = Counters()
    receiver = compiled.Receiver("mavlink", drops, sysid=4, compid=191, key=KEY if keyed else None)
    for unit in units:
        heard = python.feed(unit)
        assert receiver.feed(unit) == heard, unit.hex()
        assert receiver.sender == (python.sender_of(unit) if heard else None)
    assert dict(drops) == dict(python.drops)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), keyed=st.booleans(), count=st.integers(1, 120))
def test_the_receiver_is_the_framing_on_hostile_units(compiled: ModuleType, seed: int, keyed: bool,
                                                       count: int) -> None:
    _feed_both(compiled, hostile_units(seed, keyed, count), keyed)


def test_hostile_units_reach_every_drop_reason(compiled: ModuleType) -> None:
    # the random traffic above can fail: it reaches each reason the framing counts
    reached: set[str] = set()
    for keyed in (False, True):
        python = MavlinkFraming(4, 191, signing=Signing(KEY) if keyed else None)
        for seed in range(20):
            for unit in hostile_units(seed, keyed, 120):
                python.feed(unit)
        reached |= set(python.drops)
    assert {"noise", "crc", "truncated", "mavlink1", "unsigned", "signature", "replay", "other_message",
            "other_payload_type", "not_for_us"} <= reached


def test_the_replay_table_forgets_the_streams_signing_forgets(compiled: ModuleType) -> None:
    """More streams than are kept: both forget the least recently heard; a forgotten stream is new again, and
    within the new-stream window an older frame of it is accepted by both, beyond it refused by both."""
    rng = random.Random(7)
    units = []
    base = signing_timestamp(T0)
    for n in range(STREAMS_KEPT + 300):
        sysid, compid, link = 1 + n % 250, 1 + n // 250, 0
        units.append(frame(TUNNEL, tunnel_payload(encode(_messages(rng, 1)[0])), seq=0, sysid=sysid, compid=compid,
                           key=KEY, link_id=link, timestamp=base + n))
    for n in (0, 1, 299, 300, 301, STREAMS_KEPT + 299):  # old frames of forgotten and of kept streams
        unit = bytearray(units[n])
        sysid, compid = unit[5], unit[6]
        units.append(frame(TUNNEL, tunnel_payload(encode(_messages(rng, 1)[0])), seq=0, sysid=sysid, compid=compid,
                           key=KEY, link_id=0, timestamp=base + n - 1))
        units.append(frame(TUNNEL, tunnel_payload(encode(_messages(rng, 1)[0])), seq=0, sysid=sysid, compid=compid,
                           key=KEY, link_id=0, timestamp=base - NEW_STREAM_WINDOW))
    python = MavlinkFraming(4, 191, signing=Signing(KEY))
    accepted = [bool(python.feed(unit)) for unit in units]
    tail = accepted[STREAMS_KEPT + 300:]
    # each re-heard stream pushes out the least recent one: 300 and 301 are forgotten by their turn too
    assert tail[::2] == [True] * 5 + [False]  # an older frame: new within the window, a replay on a kept stream
    assert tail[1::2] == [False] * 6  # beyond the window behind the newest: refused either way
    _feed_both(compiled, units, keyed=True)


def _encoders(compiled: ModuleType, keyed: bool) -> tuple[MavlinkFraming, Any]:
    python = MavlinkFraming(7, 191, target=3, signing=Signing(KEY, link_id=2, clock=lambda: T0) if keyed else None)
    twin = compiled.Encoder("mavlink", sysid=7, compid=191, target=3, key=KEY if keyed else None, link_id=2)
    twin.timestamp = signing_timestamp(T0) - 1 if keyed else 0
    return python, twin


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), keyed=st.booleans())
def test_the_encoder_sends_what_the_framing_sends(compiled: ModuleType, seed: int, keyed: bool) -> None:
    rng = random.Random(seed)
    python, twin = _encoders(compiled, keyed)
    for _ in range(rng.randrange(1, 20)):
        if rng.random() < 0.2:
            assert twin.heartbeat() == python.heartbeat()
        else:
            batch = _messages(rng, rng.randrange(0, 40))
            assert twin.encode_batch(batch) == ([b"".join(python.encode_batch(batch))] if batch else [])


def test_a_shared_framing_sends_through_the_encoder(compiled: ModuleType) -> None:
    """After share_sending, the framing's HEARTBEATs and the outlet's TUNNELs go on one sequence and one signing
    clock: a receiver with the key takes them all, none is a replay."""
    python, twin = _encoders(compiled, keyed=True)
    first = python.heartbeat()
    python.share_sending(twin)
    units = [first, twin.encode_batch(_messages(random.Random(1), 3))[0], python.heartbeat(),
             *python.encode_batch(_messages(random.Random(2), 20)), python.heartbeat()]
    frames = MavlinkStreamReader(Counters()).feed(b"".join(units))
    assert [wire[4] for wire in frames] == list(range(6))
    receiver = MavlinkFraming(3, 191, signing=Signing(KEY))  # the encoders' target
    assert sum(len(receiver.feed(wire)) for wire in frames) == 23
    assert dict(receiver.drops) == {"other_message": 3}  # the HEARTBEATs: signed, in order, not ours to take


def test_pymavlink_reads_what_the_encoder_sends(compiled: ModuleType) -> None:
    from pymavlink.dialects.v20 import common as mavlink2

    for keyed in (False, True):
        _, twin = _encoders(compiled, keyed)
        twin.timestamp = 0 if not keyed else signing_timestamp(T0)
        batch = _messages(random.Random(3), 20)
        reader = mavlink2.MAVLink(None, srcSystem=9, srcComponent=1)
        if keyed:
            reader.signing.secret_key = KEY
            reader.signing.sign_outgoing = False
        got = reader.parse_buffer(twin.encode_batch(batch)[0] + twin.heartbeat())
        assert [m.get_type() for m in got] == ["TUNNEL", "TUNNEL", "HEARTBEAT"]
        assert bytes(got[0].payload[:got[0].payload_length]) == b"".join(map(encode, batch[:16]))
        assert (got[0].payload_type, got[0].target_system, got[0].get_srcSystem()) == (0xB571, 3, 7)
        assert got[0].get_signed() == keyed


def test_bad_arguments_name_themselves(compiled: ModuleType) -> None:
    import pytest

    with pytest.raises(ValueError, match="signing key is 32 bytes, got 5"):
        compiled.Receiver("mavlink", Counters(), key=b"short")
    with pytest.raises(ValueError, match=r"mavlink sysid must be 1\.\.255, got 0"):
        compiled.Encoder("mavlink", sysid=0)
    with pytest.raises(ValueError, match="48 bits"):
        compiled.Encoder("mavlink").timestamp = 1 << 48
