"""Wire codec and engine rates beside bare struct (issue: foundation)."""

from __future__ import annotations

import random
import struct
from collections.abc import Iterator

from vstig_hw import Message, Op, Stigmergy, decode, encode
from vstig_hw.engine import larger_value_wins

from .registry import Result, benchmark, rate

_N = 100_000


def _random_messages(seed: int = 1) -> list[Message]:
    rng = random.Random(seed)
    return [Message(Op(rng.getrandbits(1)), rng.getrandbits(15), rng.getrandbits(16),
                    rng.randrange(1, 65536), rng.getrandbits(16)) for _ in range(_N)]


@benchmark("wire")
def codec() -> Iterator[Result]:
    messages = _random_messages()
    buffers = [encode(m) for m in messages]
    unpack = struct.Struct(">HHHH").unpack
    pack = struct.Struct(">HHHH").pack

    def bare_unpack() -> int:
        for b in buffers:
            unpack(b)
        return _N

    def our_decode() -> int:
        for b in buffers:
            decode(b)
        return _N

    words = [tuple(m) for m in messages]

    def bare_pack() -> int:
        for w in words:
            pack(*w)
        return _N

    def our_encode() -> int:
        for m in messages:
            encode(m)
        return _N

    unpack_rate = rate(bare_unpack)
    yield Result("wire.decode", rate(our_decode), "msg/s", "struct.unpack('>HHHH')", unpack_rate)
    pack_rate = rate(bare_pack)
    yield Result("wire.encode", rate(our_encode), "msg/s", "struct.pack('>HHHH')", pack_rate)


def realistic_mix(n: int, robots: int = 50, keys: int = 64, seed: int = 7) -> list[Message]:
    """Traffic a robot hears in a busy swarm: fresh PUTs, stale repeats, conflicts, GETs."""
    rng = random.Random(seed)
    clock = [1] * keys
    out = []
    for _ in range(n):
        key = rng.randrange(keys)
        roll = rng.random()
        sender = rng.randrange(robots)
        if roll < 0.25:  # a fresh write
            clock[key] = clock[key] % 65535 + 1
            out.append(Message(Op.PUT, key, rng.getrandbits(16), clock[key], sender))
        elif roll < 0.45:  # a stale or duplicate PUT being re-broadcast
            out.append(Message(Op.PUT, key, 7, max(1, clock[key] - rng.randrange(3)), sender))
        elif roll < 0.55:  # a simultaneous write by another robot: a conflict
            out.append(Message(Op.PUT, key, rng.getrandbits(16), clock[key], sender))
        else:  # a GET carrying the asker's view
            out.append(Message(Op.GET, key, 7, max(0, clock[key] - rng.randrange(2)), sender))
    return out


@benchmark("engine")
def receive() -> Iterator[Result]:
    mix = realistic_mix(_N)
    buffers = [encode(m) for m in mix]
    unpack = struct.Struct(">HHHH").unpack

    def engine_receive() -> int:
        engine = Stigmergy(1000, onconflict=larger_value_wins)
        feed = engine.receive
        for m in mix:
            feed(m)
        engine.drain()
        return _N

    def bare_unpack() -> int:
        for b in buffers:
            unpack(b)
        return _N

    yield Result("engine.receive", rate(engine_receive), "msg/s", "struct.unpack('>HHHH')", rate(bare_unpack))
    yield Result("engine.receive_vs_goal", rate(engine_receive), "msg/s", "goal 300k msg/s", 300_000.0)
