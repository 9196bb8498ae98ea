"""Serial writes go straight to the port's fd: no select while the device takes them, a bounded wait when not."""

from __future__ import annotations

import os
import select
import time
import tty
from collections.abc import Iterator
from typing import Any

import pytest

from vstig_hw.transports.serial import SerialTransport


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    yield master, os.ttyname(slave)
    os.close(master)
    os.close(slave)


def _read_all(master: int) -> bytes:
    data = b""
    while select.select([master], [], [], 0.2)[0]:
        data += os.read(master, 65536)
    return data


def test_a_write_the_device_takes_calls_no_select(pty: tuple[int, str], monkeypatch: pytest.MonkeyPatch) -> None:
    master, path = pty
    port = SerialTransport(path, preamble=b"\x00")
    port.open()
    calls: list[Any] = []
    real = select.select

    def counted(*args: Any) -> Any:
        if args[1]:  # a wait to write; another thread's wait to read (a reader of an earlier test) is not ours
            calls.append(args)
        return real(*args)

    monkeypatch.setattr(select, "select", counted)  # pyserial's write selects after every os.write
    try:
        for i in range(100):
            port.write(bytes([1, i, 2]))
        assert port.write_nowait(b"tail") is None
    finally:
        monkeypatch.undo()
        port.close()
    assert calls == []
    assert _read_all(master) == b"\x00" + b"".join(bytes([1, i, 2]) for i in range(100)) + b"tail"
    assert port.counters["tx"] == 101


def test_a_device_that_stops_taking_costs_one_timeout_and_the_next_write_starts_clean(pty: tuple[int, str]) -> None:
    master, path = pty
    port = SerialTransport(path, write_timeout=0.2, preamble=b"\x00")
    port.open()
    try:
        port.write(b"first")
        begun = time.monotonic()
        rest = port.write_nowait(bytes(range(1, 200)) * 1000)  # ~200 kB: far more than a pty holds
        assert rest is not None and 0 < len(rest) < 199_000  # it took what fit, and did not wait for the rest
        assert time.monotonic() - begun < 0.1
        begun = time.monotonic()
        port.write(rest)  # the far end never reads: the wait is bounded by write_timeout
        assert 0.15 < time.monotonic() - begun < 1.0
        assert port.counters["tx_timeout"] == 1
        _read_all(master)  # the far end reads again
        port.write(b"next")
    finally:
        port.close()
    assert _read_all(master) == b"\x00next"  # half a frame went before: the preamble resynchronises the receiver
