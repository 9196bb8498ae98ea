"""The DeviceTransport base's state machine (outage -> backoff -> reconnect, counters), over a tiny fake device.

The base is pure policy, so a device that is a list and a flag shows all of it; the
real devices (ptys, python-can buses, Zenoh sessions, robots' sockets) are tested
through it in tests/links, tests/socketcan and tests/cli.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import pytest

from vstig_hw.transports.base import Backoff, DeviceTransport, DeviceUnreachable, TransportError


class Shelf:
    """The fake device's world: whether it is plugged in, what it holds, what it took."""

    def __init__(self) -> None:
        self.present = True
        self.reachable = True
        self.works_once_open = True  # False: it opens, then its first call fails (a CAN interface that is down)
        self.incoming: list[bytes] = []
        self.taken: list[bytes] = []
        self.opens = 0


class FakeTransport(DeviceTransport[bytes, Shelf]):
    device_word = "fake device"

    def __init__(self, shelf: Shelf, *, back_on_open: bool = True, backoff: tuple[float, float] = (0.05, 0.2)) -> None:
        super().__init__("fake0", backoff)
        self.shelf = shelf
        self.back_on_open = back_on_open  # type: ignore[misc]  # a class setting, varied here per test

    def _open_device(self) -> Shelf:
        self.shelf.opens += 1
        if not self.shelf.reachable:
            raise DeviceUnreachable("no fake router reachable")
        if not self.shelf.present:
            raise TransportError("fake device fake0: no such device")
        return self.shelf

    def _close_device(self, device: Shelf) -> None:
        pass

    def _check(self, device: Shelf) -> None:
        if not device.present or not device.works_once_open:
            raise OSError(19, "No such device")

    def _read_device(self, device: Shelf, timeout: float) -> list[bytes]:
        self._check(device)
        units, device.incoming[:] = list(device.incoming), []
        return units

    def _write_device(self, device: Shelf, unit: bytes) -> None:
        self._check(device)
        device.taken.append(unit)
        self._sent()


def _until(condition: Callable[[], bool], seconds: float = 5.0) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if condition():
            return
    raise AssertionError("never happened")


def test_backoff_starts_at_initial_and_doubles_to_the_cap() -> None:
    backoff = Backoff(0.1, 0.5)
    backoff.start(100.0)
    waits = [backoff.next_at - 100.0]
    for _ in range(4):
        backoff.failed(100.0)
        waits.append(backoff.next_at - 100.0)
    assert waits == pytest.approx([0.1, 0.2, 0.4, 0.5, 0.5])
    backoff.start(200.0, at_once=True)  # first try now, then `initial`, doubling
    assert backoff.next_at == 200.0
    backoff.failed(200.0)
    assert backoff.next_at == pytest.approx(200.1)


def test_an_outage_is_counted_once_retried_with_backoff_and_its_end_counted(
        caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    shelf = Shelf()
    transport = FakeTransport(shelf, backoff=(0.1, 0.4))
    transport.open()
    shelf.incoming.append(b"a")
    assert transport.read(0.01) == [b"a"] and transport.counters["rx"] == 1

    shelf.present = False  # unplugged
    assert transport.read(0.01) == []
    assert not transport.connected and transport.counters["lost"] == 1
    assert transport.last_error == "[Errno 19] No such device"
    opens = shelf.opens
    start = time.monotonic()
    while time.monotonic() - start < 1.0:  # the caller keeps reading; the device stays away
        assert transport.read(0.05) == []
    # tries at 0.1, 0.3, 0.7 s (0.1 s doubling to 0.4): a fixed retry would make ~20; a loaded machine fewer
    assert 1 <= shelf.opens - opens <= 4, shelf.opens - opens
    assert transport.counters["lost"] == 1 and transport.counters["reconnects"] == 0

    sent_at = time.monotonic()
    transport.write(b"x")  # gone: dropped and counted, never waited for
    assert time.monotonic() - sent_at < 0.05
    assert transport.counters["tx_dropped"] == 1 and shelf.taken == []

    shelf.present = True  # plugged back
    _until(lambda: transport.read(0.05) == [] and transport.connected)
    assert transport.counters["reconnects"] == 1 and transport.last_error is None
    transport.write(b"y")
    shelf.incoming.append(b"b")
    assert shelf.taken == [b"y"] and transport.read(0.01) == [b"b"]
    assert (transport.counters["tx"], transport.counters["rx"], transport.counters["lost"]) == (1, 2, 1)
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert said[0].startswith("fake0: fake device lost ([Errno 19] No such device)")
    assert said[1].startswith("fake0: fake device back after ") and len(said) == 2


def test_a_device_that_must_work_once_is_back_only_then_and_an_early_failure_is_the_same_outage() -> None:
    shelf = Shelf()
    transport = FakeTransport(shelf, back_on_open=False, backoff=(0.02, 0.08))
    transport.open()
    shelf.works_once_open = False  # opens, but every call fails (an interface that is down)
    transport.write(b"x")
    assert transport.counters["lost"] == 1 and transport.counters["tx_dropped"] == 1
    _until(lambda: transport.read(0.05) == [] and shelf.opens >= 4)  # reopened, failed at once, again...
    assert transport.counters["lost"] == 1 and transport.counters["reconnects"] == 0
    assert transport._backoff.delay == pytest.approx(0.08)  # grown to the cap: the same outage all along
    shelf.works_once_open = True
    _until(lambda: transport.read(0.05) == [] and transport.counters["reconnects"] == 1)
    assert transport.connected and transport.counters["lost"] == 1


def test_an_unreachable_device_at_open_is_retried_not_raised() -> None:
    shelf = Shelf()
    shelf.reachable = False
    transport = FakeTransport(shelf, backoff=(0.02, 0.1))
    transport.open()  # returns: the router may come later
    assert not transport.connected and transport.counters["unreachable"] == 1
    assert transport.last_error == "no fake router reachable"
    transport.write(b"x")
    assert transport.counters["tx_dropped"] == 1
    shelf.reachable = True
    _until(lambda: transport.read(0.05) == [] and transport.connected)
    assert transport.counters["reconnects"] == 1 and transport.counters["lost"] == 0


def test_use_before_open_names_the_device_and_after_close_is_quiet() -> None:
    transport = FakeTransport(Shelf())
    with pytest.raises(TransportError, match="fake device fake0: not open"):
        transport.read(0.01)
    with pytest.raises(TransportError, match="not open"):
        transport.write(b"x")
    with transport:
        assert transport.connected
    assert not transport.connected
    started = time.monotonic()
    assert transport.read(0.05) == []  # a reader racing close() waits out its timeout, no spin
    assert time.monotonic() - started >= 0.04
    transport.write(b"x")
    assert transport.counters["tx_dropped"] == 1 and transport.counters["lost"] == 0
