"""python-can's real slcan driver on a pty, with an slcan adapter played on the master side."""

from __future__ import annotations

import os
import queue
import select
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.links import Link
from vstig_hw.links.can import can_link

_ACK = {"t": b"z\r", "T": b"Z\r"}  # what CANable/Lawicel adapters answer to a transmit


class SlcanAdapter:
    """The adapter end of a pty: answers slcan commands and exchanges t/T frame lines."""

    def __init__(self) -> None:
        self.master, slave = os.openpty()
        self.path = os.ttyname(slave)
        self._slave = slave  # kept open so the pty survives until python-can opens it
        self.commands: queue.Queue[str] = queue.Queue()  # every line the host wrote
        # Closing an fd does not wake a thread blocked reading it: unplug() wakes it through this pipe.
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        pending = b""
        while True:
            readable, _, _ = select.select([self.master, self._wake_r], [], [])
            if self._wake_r in readable:
                return
            try:
                chunk = os.read(self.master, 4096)
            except OSError:  # the host side closed
                return
            pending += chunk
            *lines, pending = pending.split(b"\r")
            for raw in lines:
                line = raw.decode()
                self.commands.put(line)
                reply = _ACK.get(line[:1], b"\r")
                try:
                    os.write(self.master, reply)
                except OSError:
                    return

    def inject(self, line: str) -> None:
        """A frame heard on the adapter's bus, as the adapter reports it."""
        os.write(self.master, line.encode() + b"\r")

    def next_frame_line(self, deadline_s: float = 20.0) -> str:
        end = time.monotonic() + deadline_s
        while time.monotonic() < end:
            try:
                line = self.commands.get(timeout=0.1)
            except queue.Empty:
                continue
            if line[:1] in ("t", "T", "d", "D", "b", "B"):
                return line
        raise AssertionError("the host sent no frame within the deadline")

    def unplug(self) -> None:
        os.write(self._wake_w, b"x")
        self._thread.join(timeout=20)
        assert not self._thread.is_alive(), "the adapter thread did not stop"
        for fd in (self.master, self._slave, self._wake_r, self._wake_w):
            os.close(fd)


@pytest.fixture
def adapter() -> Iterator[SlcanAdapter]:
    adapter = SlcanAdapter()
    yield adapter
    adapter.unplug()


def _receive_until(link: Link[can.Message], want: int, deadline_s: float = 20.0) -> list[Message]:
    got: list[Message] = []
    end = time.monotonic() + deadline_s
    while len(got) < want and time.monotonic() < end:
        got.extend(h.message for h in link.receive(0.05))
    return got


def test_slcan_driver_carries_our_frames_both_ways(adapter: SlcanAdapter) -> None:
    link = can_link("slcan", adapter.path, robot_id=1, bitrate=500_000, sleep_after_open=0)
    link.open()
    try:
        setup = [adapter.commands.get(timeout=20) for _ in range(4)]
        assert "S6" in setup and setup[-1] == "O"  # 500 kbit/s, then open: python-can drove the adapter
        link.send(Message(Op.PUT, 1, 42, 3, 1))
        # firmware_spec/SPEC.md 6.5.2: 0x600 | PUT << 8 | node 1, DLC 8, the 8 wire bytes
        assert adapter.next_frame_line() == "t60180001002A00030001"
        adapter.inject("t7058812CBEEF01020009")  # vector: GET from node 5 carrying robot 9's entry
        adapter.inject("t1058812CBEEF01020009")  # not our scheme: filtered out by python-can
        assert _receive_until(link, 1) == [Message(Op.GET, 300, 0xBEEF, 258, 9)]
    finally:
        link.close()


def test_engine_over_slcan_answers_a_stale_get(adapter: SlcanAdapter) -> None:
    link = can_link("slcan", adapter.path, robot_id=7, extended=True, sleep_after_open=0)
    link.open()
    try:
        engine = Stigmergy(7)
        engine.put(5, 1234)  # timestamp 1
        engine.drain()
        adapter.inject("T18010009" + "8" + "8005000000000009")  # node 9 asks for key 5, holding nothing
        for heard in _receive_until(link, 1):
            engine.receive(heard)
        link.send_many(engine.drain())
        # the answer: a PUT from node 7 under 0x18000000 | 0 << 16 | 7 carrying (5, 1234, ts 1, robot 7)
        assert adapter.next_frame_line() == "T1800000780005" + "04D200010007"
    finally:
        link.close()


def test_unplugged_adapter_is_reconnected_when_it_comes_back(tmp_path: Path) -> None:
    first = SlcanAdapter()
    port = tmp_path / "ttyCAN0"  # a stable name like /dev/serial/by-id/..., pointing at whichever pty is live
    port.symlink_to(first.path)
    link = can_link("slcan", str(port), robot_id=1, sleep_after_open=0)
    link.open()
    second = None
    try:
        first.unplug()
        port.unlink()
        deadline = time.monotonic() + 20
        while link.transport.connected and time.monotonic() < deadline:
            link.receive(0.05)
        assert not link.transport.connected and link.transport.counters["lost"] == 1
        second = SlcanAdapter()
        port.symlink_to(second.path)
        got: list[Message] = []
        deadline = time.monotonic() + 30
        while not got and time.monotonic() < deadline:
            if link.transport.connected:
                second.inject("t6028000100050001000A")
            got = [h.message for h in link.receive(0.05)]
        assert got == [Message(Op.PUT, 1, 5, 1, 10)]
        assert link.transport.counters["reconnects"] == 1
    finally:
        link.close()
        if second is not None:
            second.unplug()
