"""The C codec against the Python code on random input, both ways.

Messages: 10,000 random messages encoded by C and decoded by Python, and the
reverse. Framings: C frames fed to Python receivers and Python frames to C ones,
and random noisy streams given to both, which must deliver the same messages and
count the same drops.
"""

from __future__ import annotations

import random

from adapters import epuck_reassembler, epuck_words, nonzero, serial_framing, xbee_receiver
from conftest import Driver, results
from traffic import xbee_stream

from vstig_hw import Message, Op, decode, encode

N = 10_000


def _random_messages(rng: random.Random, n: int) -> list[Message]:
    return [Message(rng.choice((Op.PUT, Op.GET)), rng.randrange(0x8000), rng.randrange(0x10000),
                    rng.randrange(0x10000), rng.randrange(0x10000)) for _ in range(n)]


def test_c_encodes_python_decodes(driver: Driver) -> None:
    msgs = _random_messages(random.Random(1), N)
    lines = driver.run(f"encode {m.op.name} {m.key} {m.value} {m.timestamp} {m.robot}" for m in msgs)
    assert [decode(bytes.fromhex(line)) for line in lines] == msgs


def test_python_encodes_c_decodes(driver: Driver) -> None:
    msgs = _random_messages(random.Random(2), N)
    lines = driver.run(f"decode {encode(m).hex()}" for m in msgs)
    assert lines == [f"{m.op.name} {m.key} {m.value} {m.timestamp} {m.robot}" for m in msgs]


def test_c_and_python_compare_timestamps_alike(driver: Driver) -> None:
    from vstig_hw.timestamps import is_newer, next_timestamp

    rng = random.Random(3)
    pairs = [(rng.randrange(0x10000), rng.randrange(0x10000)) for _ in range(N)]
    pairs += [(a, (a + d) & 0xFFFF) for a in (0, 1, 0x7FFF, 0x8000, 0xFFFF) for d in (0, 1, 0x7FFF, 0x8000, 0x8001)]
    lines = driver.run(f"newer {a} {b}" for a, b in pairs)
    assert lines == [str(int(is_newer(a, b))) for a, b in pairs]
    assert driver.run(f"next {a}" for a, _ in pairs[:1000]) == [str(next_timestamp(a)) for a, _ in pairs[:1000]]


def test_frames_agree_both_ways(driver: Driver) -> None:
    msgs = _random_messages(random.Random(4), 1000)
    cobs8, epuck4, kilobot = serial_framing("cobs8"), serial_framing("epuck4"), serial_framing("kilobot")
    ohc = serial_framing("kilobot-ohc")
    c_cobs8 = driver.run(f"cobs8 {encode(m).hex()}" for m in msgs)
    assert c_cobs8 == [cobs8.encode(m)[0].hex() for m in msgs]
    assert cobs8.feed(bytes.fromhex("".join(c_cobs8))) == msgs
    c_epuck = driver.run(f"epuck4 {encode(m).hex()}" for m in msgs)
    assert [line.split()[:3] for line in c_epuck] == [[w.hex() for w in epuck_words(m)] for m in msgs]
    assert [line.split()[3:] for line in c_epuck] == [[f.hex() for f in epuck4.encode(m)] for m in msgs]
    assert epuck4.feed(bytes.fromhex("".join("".join(line.split()[3:]) for line in c_epuck))) == msgs
    c_kilo = driver.run(f"kilobot {encode(m).hex()} 86" for m in msgs)
    assert [line.split()[1] for line in c_kilo] == [kilobot.encode(m)[0].hex() for m in msgs]
    assert driver.run(f"ohc {encode(m).hex()} 6 86" for m in msgs[:200]) == [ohc.encode(m)[0].hex() for m in msgs[:200]]
    python_stream = b"".join(f for m in msgs for f in cobs8.encode(m))
    assert driver.one(f"cobs8_rx {python_stream.hex()}") == results([encode(m).hex() for m in msgs], {})


def _noisy_stream(rng: random.Random, frames: list[bytes]) -> bytes:
    """Frames with flipped bytes, cut frames, garbage runs and idle zeros mixed in."""
    out = bytearray()
    for frame in frames:
        roll = rng.random()
        if roll < 0.15:
            frame = bytearray(frame)
            frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)
        elif roll < 0.25:
            frame = frame[: rng.randrange(1, len(frame))]
        elif roll < 0.3:
            out += bytes(rng.randrange(256) for _ in range(rng.randrange(1, 90)))
        elif roll < 0.35:
            out += b"\x00" * rng.randrange(1, 3)
        out += frame
    return bytes(out)


def _python_receive(name: str, stream: bytes) -> str:
    framing = serial_framing(name)
    return results([encode(m).hex() for m in framing.feed(stream)], nonzero(framing.drops))


def test_noisy_streams_same_outcome(driver: Driver) -> None:
    rng = random.Random(5)
    cobs8, kilobot = serial_framing("cobs8"), serial_framing("kilobot")
    commands, expected = [], []
    for _ in range(200):
        msgs = _random_messages(rng, rng.randrange(1, 12))
        frames = [f for m in msgs for f in cobs8.encode(m)] + [f for m in msgs[:2] for f in kilobot.encode(m)]
        rng.shuffle(frames)
        stream = _noisy_stream(rng, frames)
        commands += [f"cobs8_rx {stream.hex() or '-'}", f"kilobot_rx 86 {stream.hex() or '-'}"]
        expected += [_python_receive("cobs8", stream), _python_receive("kilobot", stream)]
    assert driver.run(commands) == expected


def test_epuck4_reassembly_same_outcome(driver: Driver) -> None:
    """Random words from a few messages per group, with losses, repeats, clashes and ticks."""
    rng = random.Random(6)
    commands, expected = [], []
    for _ in range(300):
        msgs = _random_messages(rng, rng.randrange(1, 6))
        words = [w for m in msgs for w in epuck_words(m) if rng.random() > 0.25]
        words += [rng.choice(words) for _ in range(rng.randrange(3))] if words else []
        rng.shuffle(words)
        events: list[bytes | None] = list(words)
        for _ in range(rng.randrange(4)):
            events.insert(rng.randrange(len(events) + 1), None)  # a tick
        if rng.random() < 0.2:
            events.append((rng.randrange(1 << 32) | 0xC0000000).to_bytes(4, "big"))  # reserved index
        reassembler = epuck_reassembler(2)
        delivered = []
        for event in events:
            if event is None:
                reassembler.tick()
            elif (msg := reassembler.feed(event)) is not None:
                delivered.append(encode(msg).hex())
        commands.append("epuck4_rx 2 " + " ".join("t" if e is None else f"w:{e.hex()}" for e in events))
        expected.append(results(delivered, nonzero(reassembler.drops)))
    assert driver.run(commands) == expected


def _python_xbee(api: int, chunks: list[bytes]) -> str:
    """The XBee transport's cutting and the framing's reading of a stream (as test_xbee_streams), as the driver
    prints it."""
    transport, framing = xbee_receiver(api)
    units = [unit for chunk in chunks for unit in transport.cut(chunk)] + transport.quiet()
    frames = []
    for unit in units:
        messages = framing.feed(unit)
        if messages:
            sender = framing.sender_of(unit)
            carried = ",".join(encode(m).hex() for m in messages)
            frames.append(f"{'-' if sender is None else f'{sender:016x}'}={carried}")
    drops = {name.removeprefix("drop_"): n for name, n in nonzero(transport.counters).items()
             if name.startswith("drop_")}
    drops.update(nonzero(framing.drops))
    return f"{';'.join(frames) or '-'} {results([], drops)}"


def test_xbee_streams_same_outcome(driver: Driver) -> None:
    """Hostile XBee streams in both API modes, cut into random chunks: the same frames, senders and drops."""
    rng = random.Random(7)
    commands, wants = [], []
    for case in range(400):
        api = 1 + case % 2
        stream = xbee_stream(rng, api == 2)
        cuts = sorted(rng.sample(range(1, len(stream)), min(len(stream) - 1, rng.randrange(0, 12))))
        chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
        commands.append(f"xbee_rx {api} {' '.join(chunk.hex() for chunk in chunks)}")
        wants.append(_python_xbee(api, chunks))
    got = driver.run(commands)
    wrong = [(c, w, g) for c, w, g in zip(commands, wants, got, strict=True) if w != g]
    assert not wrong, f"{len(wrong)} differ; first: {wrong[0]}"
