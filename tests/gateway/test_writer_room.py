"""A writer's room counts the unit its thread is writing: those messages still wait for the device.

Before, `room()` read "holds nothing" once the thread had taken the unit into a blocked write, so whether an
outlet handed a second `hold` of messages depended on how far the thread had got (a race a differential test
met: the same flood left a different split between outlet and writer on the pure and the compiled Node).
"""

from __future__ import annotations

import threading
import time
from typing import Any

from vstig_hw.counters import Counters
from vstig_hw.framing import make_serial_framing
from vstig_hw.gateway.writer import LinkWriter
from vstig_hw.links.link import Link
from vstig_hw.transports.base import Transport


class StuckDevice(Transport[Any]):
    """Takes nothing at once; a write waits until `release` is set."""

    def __init__(self) -> None:
        self.name = "stuck"
        self.counters = Counters()
        self.release = threading.Event()
        self.writing = threading.Event()
        self.taken: list[Any] = []

    def open(self) -> None:
        pass

    def close(self) -> None:
        self.release.set()

    def read(self, timeout: float) -> list[Any]:
        return []

    def write(self, unit: Any) -> None:
        self.writing.set()
        self.release.wait(10)
        self.taken.append(unit)

    def write_nowait(self, unit: Any) -> Any:
        return unit

    @property
    def connected(self) -> bool:
        return True


def test_the_unit_in_a_blocked_write_still_takes_room() -> None:
    device = StuckDevice()
    writer = LinkWriter(Link("stuck", device, make_serial_framing("cobs8")), hold=8)
    try:
        writer.submit([b"unit"], 5)  # refused at once: the thread takes it and waits in the device's write
        assert device.writing.wait(5)
        time.sleep(0.05)
        assert len(writer) == 0 and not writer.idle
        assert writer.room() == 3  # 8 held at most, 5 of them in the write
        device.release.set()
        deadline = time.monotonic() + 5
        while not writer.idle and time.monotonic() < deadline:
            time.sleep(0.01)
        assert writer.idle and writer.room() == 8 and device.taken == [b"unit"]
    finally:
        writer.close(1.0)
