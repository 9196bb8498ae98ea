"""Serial framings (issue: serial links): cobs8 cost beside UART line rates, epuck4 under loss."""

from __future__ import annotations

import random
from collections.abc import Iterator

from cobs import cobs

from vstig_hw import Message, Op, encode
from vstig_hw.framing import make_serial_framing

from .registry import Result, benchmark, rate

_N = 50_000
_BITS_PER_UART_BYTE = 10  # start + 8 data + stop (8N1)


def _messages(n: int, seed: int = 3) -> list[Message]:
    rng = random.Random(seed)
    return [Message(Op(rng.getrandbits(1)), rng.getrandbits(15), rng.getrandbits(16), rng.randrange(1, 65536),
                    rng.randrange(100)) for _ in range(n)]


def line_rate(baud: int, bytes_per_message: float) -> float:
    """Messages per second a UART at `baud` can carry at most."""
    return baud / _BITS_PER_UART_BYTE / bytes_per_message


@benchmark("serial")
def cobs8() -> Iterator[Result]:
    msgs = _messages(_N)
    framing = make_serial_framing("cobs8")
    wire_bytes = len(framing.encode(msgs[0])[0])
    payloads = [encode(m) + b"\x00\x00" for m in msgs]

    def encode_and_feed() -> int:  # one read per frame: the costliest way a UART can hand us bytes
        enc, feed = framing.encode, framing.feed
        for m in msgs:
            feed(enc(m)[0])
        return _N

    def bare_cobs() -> int:  # the C codec alone, the floor under any COBS framing
        for p in payloads:
            cobs.decode(cobs.encode(p))
        return _N

    ours = rate(encode_and_feed)
    at_1m = line_rate(1_000_000, wire_bytes)
    at_115k = line_rate(115_200, wire_bytes)
    yield Result("serial.cobs8.bytes_per_msg", wire_bytes, "B/msg", "8-byte wire message", 8.0)
    yield Result("serial.cobs8.encode_feed", ours, "msg/s", "bare cobs encode+decode", rate(bare_cobs))
    yield Result("serial.cobs8.vs_1Mbaud", ours, "msg/s", "1 Mbaud line rate", at_1m)
    yield Result("serial.cobs8.vs_115200", ours, "msg/s", "115200 baud line rate", at_115k)
    yield Result("serial.cobs8.core_pct_at_1Mbaud", 100.0 * at_1m / ours, "% of a core", "goal 5%", 5.0)


def _interleaved(msgs: list[Message], senders: int) -> float:
    """No loss, but `senders` robots' words shuffled together each control step: the cost of 16 groups."""
    framing = make_serial_framing("epuck4")
    rng = random.Random(8)
    delivered = 0
    for start in range(0, len(msgs), senders):
        units = [u for m in msgs[start:start + senders] for u in framing.encode(m)]
        rng.shuffle(units)
        for unit in units:
            delivered += len(framing.feed(unit))
        framing.tick()
    return delivered / len(msgs)


@benchmark("serial")
def epuck4() -> Iterator[Result]:
    msgs = _messages(20_000, seed=4)
    for p in (0.0, 0.25, 0.5, 0.75):
        framing = make_serial_framing("epuck4")
        rng = random.Random(7)
        sent_bytes = 0
        delivered = 0
        for i, msg in enumerate(msgs):
            for unit in framing.encode(msg):
                sent_bytes += len(unit)
                if rng.random() >= p:  # each radio word lost on its own
                    delivered += len(framing.feed(unit))
            if i % 4 == 3:
                framing.tick()
        ratio = delivered / len(msgs)
        tag = f"p{int(p * 100):02d}"
        yield Result(f"serial.epuck4.delivery_{tag}", ratio, "delivered/sent", "(1-P)^3", (1 - p) ** 3)
        if delivered:
            # beside cobs8 on a radio with the same loss per frame: one 12-byte frame per message
            yield Result(f"serial.epuck4.uart_bytes_per_delivered_{tag}", sent_bytes / delivered, "B/msg",
                         "cobs8 at same loss", 12 / (1 - p))
    yield Result("serial.epuck4.delivery_4_interleaved_p00", _interleaved(msgs, senders=4), "delivered/sent",
                 "one sender at a time", 1.0)
    framing = make_serial_framing("epuck4")

    def encode_and_feed() -> int:
        enc, feed = framing.encode, framing.feed
        for m in msgs:
            for unit in enc(m):
                feed(unit)
        return len(msgs)

    yield Result("serial.epuck4.encode_feed", rate(encode_and_feed), "msg/s", "115200 baud line rate (24 B/msg)",
                 line_rate(115_200, 24))
