"""slcan under noise: how long an honest frame takes from the adapter's pty to a `recv`, with and without noise.

An adapter on a pty sends 2,000 honest frames a second (what a busy 250 kbit/s bus
gives), each stamped with a sequence number, for 2 s; the noisy run interleaves as
many bytes of noise lines (printable ASCII, line ends among them: the noise python-can's
own reader survives) as honest bytes, times NOISE_RATIO. Figures: p50 and p99 of the
frames' delay with noise against the same driver without it (the goal: <= 2x), for our
driver (`vstig_hw.transports.slcan`) and python-can's slcanBus, whose reader takes a
system call per byte and raises on each noise line (the delays of 5-30 s seen before).
Our driver also gets binary noise (any byte), which python-can's reader cannot get past.
"""

from __future__ import annotations

import os
import random
import select
import struct
import threading
import time
import tty
from collections.abc import Iterator

import can

from vstig_hw.transports.slcan import SlcanBus, frame_line

from .registry import Result, benchmark

RATE = 2000  # honest frames a second
SECONDS = 2.0
NOISE_RATIO = 4  # noise bytes per honest byte in the noisy runs
_SEQ = struct.Struct(">Q")


def _noise(size: int, binary: bool) -> bytes:
    if binary:
        return random.randbytes(size)
    letters = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789 "
    data = bytearray(random.choices(letters, k=size))
    for i in range(random.randrange(20), size, 37):  # lines of a few dozen bytes
        data[i] = 0x0D
    return bytes(data)


def _delays(driver: str, noise: str) -> list[float]:
    """Seconds from each honest frame's write on the adapter's side to the bus handing it over."""
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    path = os.ttyname(slave)
    bus: can.BusABC = SlcanBus(path) if driver == "vstig" else can.Bus(interface="slcan", channel=path,
                                                                        sleep_after_open=0)
    os.read(master, 1024)  # the commands that opened it
    written: dict[int, float] = {}
    delays: list[float] = []
    total = int(RATE * SECONDS)

    def adapter() -> None:
        start = time.perf_counter()
        for seq in range(total):
            line = frame_line(can.Message(arbitration_id=0x123, data=_SEQ.pack(seq), is_extended_id=False))
            if noise != "none":
                line = _noise(len(line) * NOISE_RATIO, noise == "binary") + b"\r" + line
            due = start + seq / RATE
            pause = due - time.perf_counter()
            if pause > 0:
                time.sleep(pause)
            while line:
                select.select([], [master], [])
                written.setdefault(seq, time.perf_counter())
                line = line[os.write(master, line):]

    writer = threading.Thread(target=adapter, daemon=True)
    writer.start()
    deadline = time.monotonic() + SECONDS * 20
    seen = 0
    try:
        while seen < total and time.monotonic() < deadline:
            try:
                frame = bus.recv(0.5)
            except (can.CanError, ValueError, IndexError):  # python-can's reader on a line it cannot parse
                continue
            if frame is not None and frame.arbitration_id == 0x123 and len(frame.data) == 8:
                seq = _SEQ.unpack(bytes(frame.data))[0]
                delays.append(time.perf_counter() - written[seq])
                seen += 1
    finally:
        writer.join(timeout=SECONDS * 20)
        bus.shutdown()
        os.close(master)
        os.close(slave)
    delays += [float("inf")] * (total - seen)  # never handed over within the deadline
    return delays


def _quantile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


@benchmark("slcan")
def noise_delay() -> Iterator[Result]:
    for driver, noise in (("vstig", "text"), ("vstig", "binary"), ("python-can", "text")):
        clean, noisy = _delays(driver, "none"), _delays(driver, noise)
        for q, label in ((0.5, "p50"), (0.99, "p99")):
            yield Result(f"slcan.{driver}_{noise}_noise_{label}_delay", _quantile(noisy, q) * 1e3, "ms",
                         f"{driver} {label} without noise", _quantile(clean, q) * 1e3)
