"""An xbee link on real ptys (pyserial) to emulated XBee modules: the AT exchange at open, both API modes, what the
module reports, damage on the line, and robots on the XBee network converging with a CAN bus through `join`.

Every frame that crosses a module's UART, either way, is parsed by Digi's digi-xbee too.
"""

from __future__ import annotations

import random
import struct
import time
import uuid
from collections.abc import Iterator
from typing import Any

import can
import pytest
from digi.xbee.models.mode import OperatingMode
from digi.xbee.packets.base import XBeePacket
from digi.xbee.packets.common import (
    ATCommPacket,
    ATCommResponsePacket,
    ReceivePacket,
    TransmitPacket,
    TransmitStatusPacket,
)
from digi.xbee.packets.factory import build_frame
from xbee_network import Host, Module, XBeeNetwork, wire

import vstig_hw
from vstig_hw import Message, Op, Stigmergy
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.framing.xbee import api_frame, transmit_request
from vstig_hw.links import Heard, Link
from vstig_hw.links.serial import serial_link
from vstig_hw.transports.base import TransportError

GATEWAY, ROBOT = 0x0013A20040000001, 0x0013A20040000002
MODES = {1: OperatingMode.API_MODE, 2: OperatingMode.ESCAPED_API_MODE}


@pytest.fixture
def network() -> Iterator[XBeeNetwork]:
    with XBeeNetwork() as net:
        yield net


def digi_packets(raw_frames: list[bytes], api: int) -> list[XBeePacket]:
    """digi-xbee's reading of frames as on the wire; each must come back out as the same bytes."""
    mode = MODES[api]
    packets = []
    for raw in raw_frames:
        plain = XBeePacket.unescape_data(bytearray(raw)) if api == 2 else bytearray(raw)
        packet = build_frame(plain, mode)
        assert bytes(packet.output(escaped=api == 2)) == raw
        packets.append(packet)
    return packets


def link_to(module: Module, api: int | None = None, **options: Any) -> Link[bytes]:
    framing = "xbee-api2" if (api or module.api) == 2 else "xbee"
    return serial_link(module.path, framing, 230400, name="radio", **options)


def receive_until(link: Link[bytes], count: int, seconds: float = 5.0) -> list[Heard]:
    heard: list[Heard] = []
    end = time.monotonic() + seconds
    while len(heard) < count and time.monotonic() < end:
        heard += link.receive(0.05)
    return heard


@pytest.mark.parametrize("api", [1, 2])
def test_open_asks_the_module_and_messages_cross_both_ways_as_digi_reads_them(network: XBeeNetwork, api: int) -> None:
    ours, theirs = network.module(GATEWAY, api=api, np=84), network.module(ROBOT, api=api)
    robot = Host(theirs)
    link = link_to(ours)
    try:
        assert ours.at_log == ["AP", "NP", "SH", "SL"]
        assert link.transport.module.address == GATEWAY and link.transport.module.max_payload == 84  # type: ignore[attr-defined]
        sent = [Message(Op(i % 2), 0x117E + i, 0x7D13, 0x1311, 0x7E7D) for i in range(25)]  # bytes mode 2 escapes
        link.send_many(sent)
        got: list[tuple[int, bytes]] = []
        end = time.monotonic() + 5
        while sum(len(rf) for _s, rf in got) < 25 * 8 and time.monotonic() < end:
            got += robot.received(0.05)
        assert [source for source, _ in got] == [GATEWAY] * 3  # 10 + 10 + 5: NP 84 holds ten messages
        assert b"".join(rf for _, rf in got) == b"".join(struct.pack(">HHHH", m[0], *m[1:]) for m in sent)
        robot.transmit(struct.pack(">HHHH", 0x8005, 6, 7, 8) + struct.pack(">HHHH", 5, 6, 7, 8))
        heard = receive_until(link, 2)
        assert [(h.message, h.sender) for h in heard] == [(Message(Op.GET, 5, 6, 7, 8), ROBOT),
                                                          (Message(Op.PUT, 5, 6, 7, 8), ROBOT)]
        time.sleep(0.2)
        link.receive(0.05)
        stats = link.stats()
        assert stats["tx_delivered"] == 1 and stats["in"] == 2 and stats["out"] == 25  # one report: no tick yet
        assert not [name for name in stats if name.startswith("drop_")]
    finally:
        link.close()
        robot.close()
    from_us = digi_packets(ours.from_host, api)
    assert [type(p) for p in from_us] == [ATCommPacket] * 4 + [TransmitPacket] * 3
    assert [p.command for p in from_us[:4]] == ["AP", "NP", "SH", "SL"]
    to_us = digi_packets(ours.to_host, api)
    assert {type(p) for p in to_us} == {ATCommResponsePacket, TransmitStatusPacket, ReceivePacket}
    assert [bytes(p.rf_data) for p in to_us if isinstance(p, ReceivePacket)] == [theirs_sent(theirs)]


def theirs_sent(module: Module) -> bytes:
    """The RF data of the one Transmit Request a robot's host sent."""
    (raw,) = module.from_host
    return bytes(build_frame(XBeePacket.unescape_data(bytearray(raw)) if module.api == 2 else bytearray(raw),
                             MODES[module.api]).rf_data)


def test_the_modules_reports_are_counted_by_delivery_status_and_event(network: XBeeNetwork) -> None:
    ours = network.module(GATEWAY, np=64)
    network.module(ROBOT)
    link = link_to(ours, dest=0x0013A2004000BEEF)  # a unicast address no module has
    try:
        link.send(Message(Op.PUT, 1, 2, 3, 4))  # the first frame asks for a report
        link.transport.write(api_frame(transmit_request(9, bytes(72))))  # more than NP: the module refuses it
        ours.inject(api_frame(bytes.fromhex("8a00")))  # Modem Status: hardware reset
        end = time.monotonic() + 5
        while sum(link.stats()[n] for n in ("tx_failed_network_ack_failure", "tx_failed_payload_too_large",
                                            "modem_reset")) < 3 and time.monotonic() < end:
            link.receive(0.05)
        stats = link.stats()
        assert (stats["tx_failed_network_ack_failure"], stats["tx_failed_payload_too_large"], stats["modem_reset"]) \
            == (1, 1, 1)
        assert stats["rx"] == 0  # the module's reports are not units for the framing
    finally:
        link.close()


def test_a_module_that_answers_nothing_is_one_clear_error_within_the_timeout(network: XBeeNetwork) -> None:
    silent = network.module(GATEWAY, api=0)  # left in transparent mode: our frames go on the air as bytes
    listener = Host(network.module(ROBOT))
    started = time.monotonic()
    with pytest.raises(TransportError) as error:
        link_to(silent, api=1)
    assert time.monotonic() - started < 2.0
    assert str(error.value) == (
        f"XBee module on {silent.path}: no answer to AT commands within 1 s at 230400 baud: the module must run "
        "API mode 1 (AP=1) at that speed (BD); set it with XCTU, or give baud= and api= to match it "
        "(docs/how-to/xbee.md)")
    time.sleep(0.2)
    assert listener.received(0.1)  # what a module in AT mode does with API frames: it sends them as data
    listener.close()


def test_a_module_in_the_other_api_mode_says_which(network: XBeeNetwork) -> None:
    module = network.module(GATEWAY, api=2)
    with pytest.raises(TransportError, match=r"it runs API mode 2 \(AP=2\) and the link speaks api=1: give api=2"):
        link_to(module, api=1)


@pytest.mark.parametrize("api", [1, 2])
def test_noise_bad_checksums_and_cut_frames_cost_only_themselves(network: XBeeNetwork, api: int) -> None:
    ours = network.module(GATEWAY, api=api)
    link = link_to(ours)
    rng = random.Random(api)
    good = [Message(Op.PUT, k, k, 1, 9) for k in range(60)]
    try:
        damage = {"noise": 0, "checksum": 0, "truncated": 0}
        for k, msg in enumerate(good):
            data = bytes((0x90,)) + ROBOT.to_bytes(8, "big") + b"\xff\xfe\x02" + struct.pack(">HHHH", msg[0], *msg[1:])
            frame = wire(data, api)
            kind = k % 4
            if kind == 1:
                ours.inject(bytes(rng.randrange(0x80, 0xFF) for _ in range(7)))  # no 0x7E in it
                damage["noise"] += 1
            elif kind == 2:
                ours.inject(wire(data, api, checksum_off=1))
                damage["checksum"] += 1
            elif kind == 3 and api == 2:
                ours.inject(frame[:9])  # cut short: the next frame starts
                damage["truncated"] += 1
            ours.inject(frame)
        heard = receive_until(link, len(good))
        stats = link.stats()
    finally:
        link.close()
    assert [h.message for h in heard] == good and {h.sender for h in heard} == {ROBOT}
    assert {reason: stats[f"drop_{reason}"] for reason in damage} == damage


@pytest.mark.parametrize("api", [1, 2])
def test_robots_on_a_lossy_xbee_network_and_a_can_bus_converge_through_join(api: int) -> None:
    channel = f"xbee-{uuid.uuid4().hex[:8]}"
    with XBeeNetwork(loss=0.3, delay=0.01, jitter=0.02, seed=api) as network:
        gateway = network.module(GATEWAY, api=api, np=73)  # DigiMesh 2.4's NP
        radios = [Host(network.module(ROBOT + i, api=api)) for i in range(4)]
        radio_robots = [Stigmergy(10 + i) for i in range(4)]
        buses = [can.Bus(interface="virtual", channel=channel, receive_own_messages=False) for _ in range(3)]
        bus_robots = [Stigmergy(20 + i) for i in range(3)]
        framing = CanFraming(CanIdScheme(), sender=0)
        for robot in radio_robots + bus_robots:
            robot.put(1, robot.robot_id)
        spec = f"serial:{gateway.path}?framing=xbee&baud=230400" + ("&api=2" if api == 2 else "")
        try:
            with vstig_hw.join(spec, f"can:virtual:{channel}", robot_id=200, period=0.05) as swarm:
                end = time.monotonic() + 30
                while time.monotonic() < end:
                    for radio, robot in zip(radios, radio_robots, strict=True):
                        for _source, rf in radio.received():
                            for words in struct.iter_unpack(">HHHH", rf):
                                robot.receive(Message(Op(words[0] >> 15), words[0] & 0x7FFF, *words[1:]))
                        robot.get(1)
                        out = b"".join(struct.pack(">HHHH", m[0], *m[1:]) for m in robot.drain())
                        if out:
                            radio.transmit(out)
                    for bus, robot in zip(buses, bus_robots, strict=True):
                        while (frame := bus.recv(0)) is not None:
                            for msg in framing.feed(frame):
                                robot.receive(msg)
                        robot.get(1)
                        for msg in robot.drain():
                            bus.send(can.Message(arbitration_id=0x600 | int(msg.op) << 8 | robot.robot_id,
                                                 data=struct.pack(">HHHH", msg[0], *msg[1:]), is_extended_id=False))
                    everyone = [r.entry(1) for r in radio_robots + bus_robots] + [swarm.entry(1)]
                    if all(e is not None and e.value == 22 for e in everyone):
                        break
                    time.sleep(0.05)
                held = {r.robot_id: r.entry(1) for r in radio_robots + bus_robots}
                stats = swarm.stats()
        finally:
            for radio in radios:
                radio.close()
            for bus in buses:
                bus.shutdown()
    assert all(e is not None and (e.value, e.robot) == (22, 22) for e in held.values()), held  # higher robot wins
    radio_stats = next(counters for name, counters in stats.items() if name != "engine" and "tx_delivered" in counters)
    assert radio_stats["in"] > 0 and radio_stats["tx_delivered"] > 0
    assert network.counters["lost"] > 0  # the network did lose frames
    assert all(m.counters["host_overflow"] == 0 for m in network.modules)
