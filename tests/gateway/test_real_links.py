"""The gateway in-process on real links: a python-can virtual bus and a pty radio through pyserial.

The virtual bus exists only inside one process, so this is where the
virtual-bus side of a bridge is tested; tests/cli runs the same bridge as a
subprocess over slcan.
"""

from __future__ import annotations

import itertools
import os
import time
import tty

import can
from waiting import wait_until

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Node
from vstig_hw.links import parse

_ids = itertools.count()


def _pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    return master, slave, os.ttyname(slave)


def test_put_on_the_bus_reaches_a_radio_robot_and_back() -> None:
    channel = f"real-{os.getpid()}-{next(_ids)}"
    master, slave, path = _pty()
    bus_robot = can.Bus(interface="virtual", channel=channel)
    bus_codec = can_framing_for(7)
    radio_codec = make_serial_framing("epuck4")
    radio_robot = Stigmergy(40)
    links = [parse(f"can:virtual:{channel}").build("bus", robot_id=200),
             parse(f"serial:{path}?framing=epuck4").build("radio", robot_id=200)]
    with Node(links, 200):
        for frame in bus_codec.encode(Message(Op.PUT, 5, 4242, 1, 7)):
            bus_robot.send(frame)
        end = time.monotonic() + 10
        while radio_robot.entry(5) is None:
            assert time.monotonic() < end, "the PUT never crossed to the radio"
            time.sleep(0.02)
            try:
                for msg in radio_codec.feed(os.read(master, 4096) if _readable(master) else b""):
                    radio_robot.receive(msg)
            except OSError:
                pass
        assert radio_robot.entry(5) == (4242, 1, 7)
        radio_robot.put(6, 99)
        for msg in radio_robot.drain():
            for unit in radio_codec.encode(msg):
                os.write(master, unit)
        heard: list[Message] = []
        while not any(m.key == 6 for m in heard):
            assert time.monotonic() < end + 10, "the radio's PUT never reached the bus"
            time.sleep(0.02)
            while (frame := bus_robot.recv(0)) is not None:
                heard += bus_codec.feed(frame)
        assert Message(Op.PUT, 6, 99, 1, 40) in heard
    bus_robot.shutdown()
    os.close(master)
    os.close(slave)


def test_a_radio_vanishing_mid_run_is_survived() -> None:
    channel = f"vanish-{os.getpid()}-{next(_ids)}"
    master, slave, path = _pty()
    bus_robot = can.Bus(interface="virtual", channel=channel)
    codec = can_framing_for(9)
    links = [parse(f"can:virtual:{channel}").build("bus", robot_id=200),
             parse(f"serial:{path}").build("radio", robot_id=200)]
    node = Node(links, 200)
    with node:
        time.sleep(0.2)
        os.close(master)  # the radio is unplugged: its pty is gone for good
        os.close(slave)
        time.sleep(0.5)
        for frame in codec.encode(Message(Op.PUT, 1, 11, 1, 9)):
            bus_robot.send(frame)
        engine = node.engine
        assert engine is not None
        wait_until(lambda: engine.has(1), 5)
        assert engine.entry(1) == (11, 1, 9)  # the rest of the gateway kept working
        node.put(2, 22)  # and sending to the vanished radio is counted, not raised
        time.sleep(0.3)
    bus_robot.shutdown()


def _readable(fd: int) -> bool:
    import select

    return bool(select.select([fd], [], [], 0.01)[0])


def test_bytes_from_a_transmit_only_link_are_counted_not_raised() -> None:
    master, slave, path = _pty()
    node = Node([parse(f"kilobot-ohc:{path}").build("ohc")], 3)
    with node:
        os.write(master, b"\x55" * 200)  # an overhead controller has nothing to say; if it did, we could not decode it
        end = time.monotonic() + 10
        while not node.stats()["ohc"]["drop_undecodable"]:
            assert time.monotonic() < end
            time.sleep(0.05)
        node.put(1, 2)  # and sending still works: one 132-byte controller packet
        data = b""
        while len(data) < 132:
            assert time.monotonic() < end + 10
            time.sleep(0.05)
            if _readable(master):
                data += os.read(master, 4096)
    assert data[0] == 0x55 and len(data) == 132
    os.close(master)
    os.close(slave)
