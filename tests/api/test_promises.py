"""What the Python API's docs promise, tried as a new user would (issue 32): a confirmed put on a radio that
echoes, a close with a budget of one, the exceptions a program must catch, a Link object, one handle per
table, bad arguments, `reachable` as data. Real links: ptys through pyserial, pyserial's loop://,
python-can's virtual bus.
"""

from __future__ import annotations

import os
import threading
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

import vstig_hw
from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.api.virtual import VirtualRobots
from vstig_hw.framing import make_serial_framing
from vstig_hw.links.serial import serial_link

ME = 60


class EchoingRadio:
    """A pty whose far end sends back every byte it is sent (a radio that hears itself); `heard` decodes them."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.heard: list[Message] = []
        self._framing = make_serial_framing("cobs8")
        self._running = True
        self._thread = threading.Thread(target=self._echo, daemon=True)
        self._thread.start()

    def _echo(self) -> None:
        import select

        while self._running:
            if select.select([self.master], [], [], 0.01)[0]:
                data = os.read(self.master, 4096)
                os.write(self.master, data)
                self.heard.extend(self._framing.feed(data))

    def close(self) -> None:
        self._running = False
        self._thread.join(2)
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def echoing() -> Iterator[EchoingRadio]:
    radio = EchoingRadio()
    yield radio
    radio.close()


@pytest.mark.parametrize("learn", [0.0, 0.3])
def test_a_confirmed_put_on_a_pty_that_echoes_raises_hears_itself(echoing: EchoingRadio, learn: float) -> None:
    with vstig_hw.join(f"serial:{echoing.path}?framing=cobs8", robot_id=ME) as swarm, \
            pytest.raises(vstig_hw.HearsItself, match=f"brings our own GETs back \\(robot id {ME}\\)"):
        swarm.put(5, 1, confirm=True, timeout=2.0, learn=learn)
    puts = {m for m in echoing.heard if m.op is Op.PUT}  # (our engine answers its own echoed GETs with it too)
    assert puts == (set() if learn else {Message(Op.PUT, 5, 1, 1, ME)})  # learning finds it before writing


@pytest.mark.parametrize("learn", [0.0, 0.3])
def test_a_confirmed_put_on_pyserials_loop_raises_hears_itself(learn: float) -> None:
    with vstig_hw.join("serial:loop://?framing=cobs8", robot_id=ME) as swarm:
        started = time.monotonic()
        with pytest.raises(vstig_hw.HearsItself) as caught:
            swarm.put(5, 1, confirm=True, timeout=2.0, learn=learn)
        # the way to write anyway, as Python says it: not the CLI's flag
        assert str(caught.value).endswith("(put(key, value, confirm=False) writes anyway)")
        assert "--no-confirm" not in str(caught.value)
        assert time.monotonic() - started < 1.0 + learn  # found at once, not at the end of the wait
        assert swarm.put(6, 2) == Entry(2, 1, ME)  # an unconfirmed put still works there


def reading(robot: Stigmergy, step: int) -> None:
    robot.get(1)


def test_a_budget_of_one_closes_at_once_once_what_it_held_back_went_out() -> None:
    """Robots reading every 10 ms, refresh on, one message per link per step: the queues never empty while
    the swarm runs (a GET each step, answers), yet close sends what was held and stops in a few steps."""
    with VirtualRobots(can_ids=[1, 2], radio_ids=[3, 4], program=reading) as robots:
        swarm = vstig_hw.join(*robots.links, robot_id=ME, budget=1, period=0.1)
        for key in (1, 2, 3):
            swarm.put(key, 5)
        time.sleep(1.0)
        started = time.monotonic()
        swarm.close()
        took = time.monotonic() - started
        after = swarm._node.stats()
    assert took < 0.5, f"close took {took:.2f} s"
    assert not any(counters.get("unsent_at_close") for counters in after.values())  # all of it went out


def test_what_a_program_must_catch_is_importable_from_vstig_hw(tmp_path: Path) -> None:
    for name in ("TransportError", "CaptureError", "NotTaken", "HearsItself", "SwarmClosed"):
        assert issubclass(getattr(vstig_hw, name), Exception) and name in vstig_hw.__all__
    with pytest.raises(vstig_hw.TransportError, match="/dev/ttyNOPE"):
        vstig_hw.join("serial:/dev/ttyNOPE", robot_id=ME)
    channel = f"promises-{time.monotonic_ns()}"
    with vstig_hw.join(f"can:virtual:{channel}", robot_id=ME) as swarm, \
            pytest.raises(vstig_hw.CaptureError, match="no-such-folder"):
        swarm.record(tmp_path / "no-such-folder" / "x.log")
    with pytest.raises(vstig_hw.SwarmClosed, match="is closed: it was closed"):
        swarm.put(1, 1)


def test_a_link_object_is_taken_open_or_not_and_closed_with_the_swarm() -> None:
    peer_master, peer_slave = os.openpty()
    tty.setraw(peer_slave)
    try:
        link = serial_link(os.ttyname(peer_slave), "cobs8")  # opened now, as serial_link does by default
        assert link.opened
        with vstig_hw.join(link, robot_id=ME) as swarm:
            swarm.put(3, 30)
            data = b""
            while b"\x00" not in data[1:]:
                data += os.read(peer_master, 64)
            assert Message(Op.PUT, 3, 30, 1, ME) in make_serial_framing("cobs8").feed(data)
        assert not link.opened  # the swarm closed it
    finally:
        os.close(peer_master)
        os.close(peer_slave)


def test_one_handle_per_table_whichever_handle_asks() -> None:
    channel = f"tables-{time.monotonic_ns()}"
    with vstig_hw.join(f"can:virtual:{channel}?extended=1", robot_id=ME) as swarm:
        two = swarm.stigmergy(2)
        assert two.stigmergy(2) is two and swarm.stigmergy(2) is two
        assert two.stigmergy(0) is swarm  # the first table, from the second's handle
        three = two.stigmergy(3)
        assert swarm.stigmergy(3) is three and three.stigmergy(2) is two
    assert two.closed and three.closed


@pytest.mark.parametrize(("call", "error", "message"), [
    (lambda s: s.put(1, None), TypeError, "value must be a number .*got None"),
    (lambda s: s.put(1, [1]), TypeError, r"value must be a number .*got \[1\]"),
    (lambda s: s.put(1, True), TypeError, "value must be a number .*got True"),
    (lambda s: s.put(None, 1), ValueError, "key must be an integer in 0..32767, got None"),
    (lambda s: s.get(None), ValueError, "key must be an integer in 0..32767, got None"),
    (lambda s: s.entry("3"), ValueError, "key must be an integer in 0..32767, got '3'"),
    (lambda s: s.put(1, 1, confirm=True, timeout=None), ValueError, "timeout must be a positive number"),
    (lambda s: s.put(1, 1, confirm=True, tries=None), ValueError, "tries must be an integer"),
    (lambda s: s.put(1, 1, confirm=True, learn=None), ValueError, "learn must be a number of seconds"),
    (lambda s: s.stigmergy(None), ValueError, "stigmergy must be an integer"),
    (lambda s: s.record(None), TypeError, "record needs a file name, got None"),
    (lambda s: s.watch(keys=3), TypeError, "keys must be a collection of keys"),
    (lambda s: s.onconflict(None), TypeError, "onconflict needs a function"),
    (lambda s: s.on_change(None), TypeError, "on_change needs a function"),
])
def test_none_and_wrong_types_are_clear_errors_naming_the_argument(call: object, error: type[Exception],
                                                                   message: str) -> None:
    channel = f"types-{time.monotonic_ns()}"
    with vstig_hw.join(f"can:virtual:{channel}", robot_id=ME) as swarm, pytest.raises(error, match=message):
        call(swarm)  # type: ignore[operator]


def test_reachable_is_the_endpoints_as_data() -> None:
    channel = f"reach-{time.monotonic_ns()}"
    with vstig_hw.join(f"can:virtual:{channel}", robot_id=ME) as swarm:
        assert swarm.reachable == {}  # a bus listens on no endpoint


def test_a_confirmed_put_whose_robot_writes_on_top_of_it_is_taken() -> None:
    """A robot that stores our write and writes the key again at once (a Buzz robot's program does): its write,
    one timestamp past ours, was built on ours."""
    channel = f"ontop-{time.monotonic_ns()}"
    bus = can.Bus(interface="virtual", channel=channel)
    from vstig_hw.framing.can import can_framing_for

    codec, robot, running = can_framing_for(7), Stigmergy(7), [True]

    def program() -> None:
        while running[0]:
            frame = bus.recv(0.01)
            for msg in codec.feed(frame) if frame is not None else []:
                robot.receive(msg)
                if msg.op is Op.PUT and msg.robot == ME:
                    robot.put(msg.key, 999)  # the out-queue keeps only this newer write: ours is never re-sent
            for msg in robot.drain():
                bus.send(codec.encode(msg)[0])

    thread = threading.Thread(target=program, daemon=True)
    thread.start()
    try:
        with vstig_hw.join(f"can:virtual:{channel}", robot_id=ME) as swarm:
            assert swarm.put(8, 80, confirm=True, timeout=2.0, tries=1) == Entry(80, 1, ME)
            result = swarm.put_future(9, 90, timeout=2.0, tries=1).result(5)
            assert result.confirmed and result.shown == Entry(999, 2, 7) and result.written == Entry(90, 1, ME)
    finally:
        running[0] = False
        thread.join(2)
        bus.shutdown()
