"""CAN: frames/s through framing + engine beside what a 1 Mbit/s bus can carry; bus cost per message.

Bit counts follow ISO 11898-1 frame layouts: classic base/extended frames and
CAN FD frames (stuff-count field, CRC-17/21 with fixed stuff bits). "Best" has no
stuff bits, "worst" the most dynamic stuffing possible.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import can

from vstig_hw import Stigmergy
from vstig_hw.engine import larger_value_wins
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.links.can import can_link

from .bench_wire import realistic_mix
from .registry import Result, benchmark, rate

_N = 50_000
_GOAL = 50_000.0  # frames/s on one core: one PC serves several saturated buses
_NOMINAL = 1_000_000  # bit/s, the classic CAN maximum
_TAIL = 1 + 2 + 7 + 3  # CRC delimiter, ACK slot + delimiter, end of frame, interframe space


def classic_bits(extended: bool = False, data_bytes: int = 8) -> tuple[int, int]:
    """(best, worst) bits on the bus for one classic data frame, interframe space included."""
    header = 1 + 11 + 1 + 1 + 18 + 1 + 2 + 4 if extended else 1 + 11 + 1 + 1 + 1 + 4
    stuffed = header + 8 * data_bytes + 15  # SOF through CRC is subject to bit stuffing
    return stuffed + _TAIL, stuffed + (stuffed - 1) // 4 + _TAIL


def fd_bits(data_bytes: int, extended: bool = False) -> tuple[tuple[int, int], tuple[int, int]]:
    """((arbitration-rate bits, data-rate bits) best, same worst) for one CAN FD frame with BRS."""
    arbitration = 1 + 11 + 1 + 1 + 18 + 1 + 1 + 1 + 1 if extended else 1 + 11 + 1 + 1 + 1 + 1 + 1  # SOF..BRS
    data_dyn = 1 + 4 + 8 * data_bytes  # ESI, DLC, data: dynamically stuffed at the data rate
    crc = 17 if data_bytes <= 16 else 21
    fixed = 4 + crc + 1 + (4 + crc) // 4  # stuff count, CRC and their fixed stuff bits (one before, one per 4)
    best = (arbitration + _TAIL - 1, data_dyn + fixed + 1)  # CRC delimiter counted at the data rate
    worst_arb = (arbitration - 1) // 4
    worst_data = (arbitration + data_dyn - 1) // 4 - worst_arb
    return best, (best[0] + worst_arb, best[1] + worst_data)


def _frames(n: int) -> list[can.Message]:
    """A busy bus: the realistic mix, sent by 50 robots under their own IDs."""
    scheme = CanIdScheme()
    framings = [CanFraming(scheme, sender) for sender in range(50)]
    return [framings[msg.robot % 50].encode(msg)[0] for msg in realistic_mix(n)]


@benchmark("can")
def throughput() -> Iterator[Result]:
    frames = _frames(_N)
    bus_max = _NOMINAL / classic_bits()[0]  # the most frames/s a saturated 1 Mbit/s bus delivers

    def framing_and_engine() -> int:
        framing = CanFraming(CanIdScheme(), sender=1)
        engine = Stigmergy(1000, onconflict=larger_value_wins)
        feed, receive = framing.feed, engine.receive
        for frame in frames:
            for msg in feed(frame):
                receive(msg)
        engine.drain()
        return _N

    core = rate(framing_and_engine)
    yield Result("can.framing+engine (no bus)", core, "frame/s", "1 Mbit/s bus max (111-bit frames)", bus_max)
    yield Result("can.framing+engine vs goal", core, "frame/s", "goal 50k frame/s", _GOAL)

    channel = f"bench-{id(frames)}"
    link = can_link("virtual", channel, robot_id=1)
    link.open()
    bare = can.Bus(interface="virtual", channel=channel + "-bare")
    sender = can.Bus(interface="virtual", channel=channel)
    bare_sender = can.Bus(interface="virtual", channel=channel + "-bare")
    try:
        def through_virtual_bus() -> int:  # python-can virtual recv + filters + framing + engine
            for frame in frames:
                sender.send(frame)
            engine = Stigmergy(1000, onconflict=larger_value_wins)
            got = 0
            while got < _N:
                for heard in link.receive(0.5):
                    engine.receive(heard.message)
                    got += 1
            return _N

        def bare_virtual_recv() -> int:  # the same frames through python-can alone
            for frame in frames:
                bare_sender.send(frame)
            for _ in range(_N):
                bare.recv(0.5)
            return _N

        def receive_side() -> float:  # the queue is filled first: time link.receive + engine alone
            for frame in frames:
                sender.send(frame)
            engine = Stigmergy(1000, onconflict=larger_value_wins)
            got, start = 0, time.perf_counter()
            while got < _N:
                for heard in link.receive(0.5):
                    engine.receive(heard.message)
                    got += 1
            return _N / (time.perf_counter() - start)

        e2e = rate(through_virtual_bus, min_seconds=1.0)
        yield Result("can.virtual send+rx+engine", e2e, "frame/s", "1 Mbit/s bus max (111-bit frames)", bus_max)
        yield Result("can.virtual send+rx+engine vs bare", e2e, "frame/s", "python-can virtual send+recv alone",
                     rate(bare_virtual_recv, min_seconds=1.0))
        yield Result("can.virtual rx+engine", max(receive_side() for _ in range(3)), "frame/s", "goal 50k frame/s",
                     _GOAL)
    finally:
        link.close()
        for bus in (bare, sender, bare_sender):
            bus.shutdown()

    messages = realistic_mix(_N)

    def encode_classic() -> int:
        CanFraming(CanIdScheme(), sender=1).encode_batch(messages)
        return _N

    def bare_message() -> int:
        for _ in messages:
            can.Message(arbitration_id=0x601, is_extended_id=False, data=b"\0" * 8)
        return _N

    yield Result("can.encode classic", rate(encode_classic), "msg/s", "bare can.Message()", rate(bare_message))


@benchmark("can")
def bus_cost() -> Iterator[Result]:
    """Bytes on the bus per message (all bits, /8) and bus time per message, classic vs CAN FD batches."""
    best, worst = classic_bits()
    classic_bytes = worst / 8
    yield Result("can.classic11 bytes/msg best", best / 8, "B", "8-byte payload", 8.0)
    yield Result("can.classic11 bytes/msg worst", worst / 8, "B", "8-byte payload", 8.0)
    yield Result("can.classic29 bytes/msg worst", classic_bits(True)[1] / 8, "B", "8-byte payload", 8.0)
    classic_us = worst / _NOMINAL * 1e6
    for n in (1, 2, 3, 4, 6, 8):
        (_, _), (arb, data) = fd_bits(8 * n)
        yield Result(f"can.fd x{n} bytes/msg worst", (arb + data) / 8 / n, "B", "classic, worst", classic_bytes)
        for data_rate in (2_000_000, 5_000_000):
            us = (arb / _NOMINAL + data / data_rate) * 1e6 / n
            yield Result(f"can.fd x{n} us/msg @1M/{data_rate // 1_000_000}M", us, "us", "classic @1M, worst",
                         classic_us)
