"""`vstig bridge`, `record`, `decode` and `replay` as processes, through emulated XBee modules on ptys.

Robots on a lossy XBee network (each on its own module, as hosts that are not vstig), robots on a
cobs8 pty radio and on a CAN bus behind an slcan adapter converge through one bridge, in both API
modes; a module that stops reading and a module buried in noise cost only their own links; a
gateway that stops reading its module loses only what the module could not hold; captures keep
every frame, and with it its sender.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from digi.xbee.models.mode import OperatingMode
from digi.xbee.packets.base import XBeePacket
from digi.xbee.packets.common import TransmitPacket
from digi.xbee.packets.factory import build_frame
from peers import PtyPeer, run_vstig, start_vstig, stop, wait_for
from robots import CanRobot, PtyRobot, Robot
from test_isolation import Listener, _counters, _fill, _paced
from xbee_network import Host, Module, XBeeNetwork, wire

from vstig_hw import Message, Op, encode
from vstig_hw.framing import make_serial_framing

GATEWAY = 0x0013A20040000001
ROBOT = 0x0013A20040000100


class XBeeRobot(Robot):
    """A robot whose radio is an XBee module: its outbox goes out in one Transmit Request per step."""

    def __init__(self, robot_id: int, module: Module) -> None:
        super().__init__(robot_id)
        self.host = Host(module)

    def _heard(self) -> list[Message]:
        return [Message(Op(w[0] >> 15), w[0] & 0x7FFF, *w[1:])
                for _source, rf in self.host.received() for w in struct.iter_unpack(">HHHH", rf)]

    def _send(self, messages: list[Message]) -> None:
        if messages:
            self.host.transmit(b"".join(encode(m) for m in messages))

    def close(self) -> None:
        self.host.close()


def _xbee(module: Module) -> str:
    return f"serial:{module.path}?framing=xbee&baud=230400" + ("&api=2" if module.api == 2 else "")


@pytest.mark.parametrize("api", [1, 2])
def test_xbee_robots_a_pty_radio_and_a_can_bus_converge_through_one_bridge(api: int) -> None:
    with XBeeNetwork(loss=0.3, delay=0.005, jitter=0.02, seed=api) as network:
        gateway = network.module(GATEWAY, api=api)
        robots: list[Robot] = [XBeeRobot(10 + i, network.module(ROBOT + i, api=api)) for i in range(3)]
        robots += [PtyRobot(30), CanRobot(40)]
        for robot in robots:
            robot.put(1, robot.id)  # the paper's task: every robot puts its id; the largest wins
        bridge = start_vstig("bridge", _xbee(gateway), robots[3].spec, robots[4].spec,  # type: ignore[attr-defined]
                             "--robot-id", "200", "--larger-value-wins", "--tick", "0.05")
        try:
            wait_for(lambda: all(r.value(1) == 40 for r in robots), 30,
                     step=lambda: ([r.step() for r in robots], time.sleep(0.05)))
        finally:
            _out, err = stop(bridge)
            for robot in robots:
                robot.close()
    assert bridge.returncode == 0, err
    radio = _counters(err, os.path.basename(gateway.path))
    assert radio["in"] > 0 and radio["tx_delivered"] > 0 and radio["out"] > 0
    assert not [name for name in radio if name.startswith("drop_")], radio  # a clean line drops nothing
    assert network.counters["lost"] > 0
    mode = OperatingMode.ESCAPED_API_MODE if api == 2 else OperatingMode.API_MODE
    for raw in gateway.from_host:  # every frame the bridge sent, read by Digi's library
        build_frame(XBeePacket.unescape_data(bytearray(raw)) if api == 2 else bytearray(raw), mode)


COUNT = 1500  # 3 s at test_isolation's 500 messages/s


def _noise(module: Module, stop_event: threading.Event) -> None:
    """Line noise, frames with bad checksums and frames cut short, among good frames from a robot, until told."""
    k = 0
    while not stop_event.is_set():
        good = wire(bytes((0x90,)) + (ROBOT + 7).to_bytes(8, "big") + b"\xff\xfe\x02" +
                    encode(Message(Op.PUT, 30000 + k % 100, k, 1 + k // 100, 77)), module.api)
        module.inject(b"\x00\xff\x55noise" + wire(b"\x90" + bytes(14), module.api, checksum_off=1) + good[:7] + good)
        k += 1
        time.sleep(0.01)


def test_a_module_that_stops_reading_and_one_buried_in_noise_cost_only_their_own_links() -> None:
    with XBeeNetwork() as network:
        deaf, noisy = network.module(GATEWAY, api=2), network.module(GATEWAY + 1, api=2)
        source, healthy = PtyPeer(), PtyPeer()
        names = {"deaf": os.path.basename(deaf.path), "noisy": os.path.basename(noisy.path)}
        bridge = start_vstig("bridge", _xbee(deaf), _xbee(noisy), f"serial:{source.path}", f"serial:{healthy.path}",
                             "--robot-id", "200", "--budget", "4000", "--no-refresh")
        echo, out = Listener(source), Listener(healthy)
        noising = threading.Event()
        noise = threading.Thread(target=_noise, args=(noisy, noising), daemon=True)
        cobs8 = make_serial_framing("cobs8")
        try:
            probe = iter(range(1, 60_000))
            wait_for(lambda: 32767 in out.arrived, 30, step=lambda: (source.write(
                cobs8.encode(Message(Op.PUT, 32767, 1, next(probe), 7))[0]), time.sleep(0.1)))
            network.set_deaf(deaf)  # from now on the module takes nothing...
            _fill(deaf)  # type: ignore[arg-type]  # ...and has not for long: its pty is full
            noise.start()
            frames = [cobs8.encode(Message(Op.PUT, i, i, 1, 7))[0] for i in range(COUNT)]
            sent = _paced(COUNT, lambda i: source.write(frames[i]))
            wait_for(lambda: len(out.arrived) > COUNT + 50, 10, step=lambda: time.sleep(0.1))
            noising.set()
            noise.join()
            stopped = time.monotonic()
        finally:
            _out, err = stop(bridge)
            for closing in (echo, out, source, healthy):
                closing.close()
    assert bridge.returncode == 0, err
    assert time.monotonic() - stopped < 3.0  # the deaf module held no stop (2 s, and the test's own slack)
    delays = sorted(out.arrived[i] - sent[i] for i in range(COUNT) if i in out.arrived)
    assert len(delays) == COUNT  # the healthy radio lost nothing
    assert statistics.median(delays) < 0.050, f"p50 {statistics.median(delays) * 1e3:.1f} ms"
    assert sum(1 for key in out.arrived if 30000 <= key < 30100) > 50  # the noisy module's good frames got through
    stuck = _counters(err, names["deaf"])
    # what the deaf module could not take waits in its own link's lines (one message per key: bounded), counted
    assert stuck.get("queued", 0) > 1000, stuck
    loud = _counters(err, names["noisy"])
    assert loud["drop_noise"] > 0 and loud["drop_checksum"] > 0 and loud["drop_truncated"] > 0, loud


def test_a_gateway_that_stops_reading_loses_only_what_its_module_could_not_hold() -> None:
    with XBeeNetwork() as network:
        gateway = network.module(GATEWAY, host_buffer=512)
        robot = XBeeRobot(10, network.module(ROBOT))
        radio = PtyRobot(30, watch=())
        bridge = start_vstig("bridge", _xbee(gateway), radio.spec, "--robot-id", "200", "--no-refresh")
        try:
            robot.put(1, 10)
            wait_for(lambda: radio.value(1) == 10, 30, step=lambda: (robot.step(), radio.step(), time.sleep(0.05)))
            os.kill(bridge.pid, signal.SIGSTOP)  # the gateway reads nothing: its pty fills, then the module's buffer
            for first in range(2, 12_802, 32):  # 400 full frames, 100 kB: more than a pty and the module hold
                robot.host.transmit(b"".join(encode(Message(Op.PUT, k, k, 1, 10)) for k in range(first, first + 32)))
            wait_for(lambda: gateway.counters["host_overflow"] > 0, 10)
            os.kill(bridge.pid, signal.SIGCONT)
            robot.put(1000, 1000)
            wait_for(lambda: radio.value(1000) == 1000, 30,
                     step=lambda: (robot.step(), radio.step(), time.sleep(0.05)))
        finally:
            os.kill(bridge.pid, signal.SIGCONT)
            _out, err = stop(bridge)
            robot.close()
            radio.close()
    assert bridge.returncode == 0, err
    assert gateway.counters["host_overflow"] > 0  # the module dropped whole frames it could not hand over...
    link = _counters(err, os.path.basename(gateway.path))
    assert not [name for name in link if name.startswith("drop_")], link  # ...so the gateway saw no broken frame


@pytest.fixture
def recorded(tmp_path: Path) -> Iterator[tuple[Path, XBeeNetwork, Module, list[Module]]]:
    """A capture of an xbee link that heard two robots' modules, and the network, still up."""
    with XBeeNetwork() as network:
        gateway = network.module(GATEWAY, api=2)
        modules = [network.module(ROBOT + i, api=2) for i in range(2)]
        hosts = [Host(module) for module in modules]
        path = tmp_path / "radio.cap"
        recorder = start_vstig("record", _xbee(gateway), "-o", str(path))
        try:
            wait_for(lambda: path.exists() and gateway.at_log[:4] == ["AP", "NP", "SH", "SL"], 30)
            time.sleep(0.3)
            for i, host in enumerate(hosts):
                host.transmit(encode(Message(Op.PUT, 10 + i, 0x7E7D, 1, 10 + i)) +
                              encode(Message(Op.GET, 20 + i, 0, 0, 10 + i)))
            wait_for(lambda: len(gateway.rx_frames()) == 2, 10)
            time.sleep(0.3)
        finally:
            _out, err = stop(recorder)
            for host in hosts:
                host.close()
        assert recorder.returncode == 0, err
        yield path, network, gateway, modules


def test_a_capture_holds_each_frame_as_the_module_sent_it_and_decodes_with_its_sender(
        recorded: tuple[Path, XBeeNetwork, Module, list[Module]]) -> None:
    path, _network, gateway, modules = recorded
    lines = path.read_text().splitlines()
    assert lines[0] == "# vstig serial capture v1"
    frames = [bytes.fromhex(line.split()[-1]) for line in lines[1:] if " xbee-api2 rx " in line]
    assert frames == gateway.rx_frames()  # whole frames, escaped as on the wire
    decoded = run_vstig("decode", str(path), "--format", "jsonl")
    assert decoded.returncode == 0, decoded.stderr
    rows = [json.loads(line) for line in decoded.stdout.splitlines()]
    assert [(r["op"], r["key"], r["value"], r["sender"]) for r in rows] == [
        ("PUT", 10, 0x7E7D, modules[0].address), ("GET", 20, 0, modules[0].address),
        ("PUT", 11, 0x7E7D, modules[1].address), ("GET", 21, 0, modules[1].address)]
    only = run_vstig("decode", str(path), "--format", "jsonl", "--sender", f"{modules[1].address:#x}", "--op", "PUT")
    assert [json.loads(line)["key"] for line in only.stdout.splitlines()] == [11]
    analyzed = run_vstig("analyze", str(path))
    assert analyzed.returncode == 0, analyzed.stderr
    assert [line.split()[1] for line in analyzed.stdout.splitlines() if line.startswith("sender ")] == [
        f"0x{m.address:016X}" for m in modules]  # by their 64-bit addresses, as --sender takes them
    mcap = path.with_suffix(".mcap")
    assert run_vstig("decode", str(path), "-o", str(mcap)).returncode == 0
    again = run_vstig("decode", str(mcap), "--format", "jsonl")
    assert [json.loads(line)["sender"] for line in again.stdout.splitlines()] == [r["sender"] for r in rows]


def test_a_capture_replays_onto_another_module_as_transmit_requests(
        recorded: tuple[Path, XBeeNetwork, Module, list[Module]]) -> None:
    path, network, _gateway, _modules = recorded
    target = network.module(GATEWAY + 9)
    done = run_vstig("replay", str(path), "--onto", f"serial:{target.path}?framing=xbee&baud=230400",
                     "--ignore-timestamps")
    assert done.returncode == 0, done.stderr
    sent = [build_frame(bytearray(raw), OperatingMode.API_MODE) for raw in target.from_host]
    carried = [bytes(p.rf_data) for p in sent if isinstance(p, TransmitPacket)]
    assert b"".join(carried) == b"".join(encode(m) for m in (
        Message(Op.PUT, 10, 0x7E7D, 1, 10), Message(Op.GET, 20, 0, 0, 10),
        Message(Op.PUT, 11, 0x7E7D, 1, 11), Message(Op.GET, 21, 0, 0, 11)))  # re-encoded, in API mode 1


def test_a_stop_while_the_bridge_asks_a_silent_module_ends_within_the_at_timeout() -> None:
    with XBeeNetwork() as network:
        silent = network.module(GATEWAY, api=0)  # in AT mode: our API frames go on the air as bytes
        listener = Host(network.module(ROBOT))
        radio = PtyPeer()
        bridge = start_vstig("bridge", _xbee(silent), f"serial:{radio.path}", "--robot-id", "200")
        try:
            wait_for(lambda: bool(listener.received(0.05)), 30)  # the AT commands are out: the bridge waits
            stopped = time.monotonic()
            _out, err = stop(bridge)
            took = time.monotonic() - stopped
        finally:
            listener.close()
            radio.close()
    assert took < 2.0, took  # at most the 1 s the module is given
    # A stop that lands while the module is asked ends the bridge at once, as asked (exit 0: the open is left
    # to the process's end); one that lands after the 1 s finds the open failed, and says why (exit 1).
    if bridge.returncode == 0:
        assert "Traceback" not in err, err
    else:
        assert bridge.returncode == 1 and err.strip().splitlines()[-1] == (
            f"Error: XBee module on {silent.path}: no answer to AT commands within 1 s at 230400 baud: the module "
            "must run API mode 1 (AP=1) at that speed (BD); set it with XCTU, or give baud= and api= to match it "
            "(docs/how-to/xbee.md)")


def test_sniff_shows_each_message_with_its_module_and_what_trusting_one_module_refuses() -> None:
    with XBeeNetwork() as network:
        radio = network.module(GATEWAY)
        trusted, other = (Host(network.module(ROBOT + i)) for i in range(2))
        name = os.path.basename(radio.path)
        sniff = start_vstig("sniff", _xbee(radio), "--jsonl", "--trust", f"{name}={trusted.module.address:#x}")
        rows: list[dict[str, object]] = []
        reader = threading.Thread(target=lambda: rows.extend(json.loads(line) for line in sniff.stdout), daemon=True)
        reader.start()
        try:
            wait_for(lambda: radio.at_log[:4] == ["AP", "NP", "SH", "SL"], 30)
            time.sleep(0.3)
            for key, host in enumerate((trusted, other), 1):
                host.transmit(encode(Message(Op.PUT, key, 100 + key, 1, 7)))
            wait_for(lambda: len(rows) == 2, 10)
        finally:
            _out, err = stop(sniff)
            trusted.close()
            other.close()
    assert sniff.returncode == 0, err
    assert sorted((r["key"], r["sender"], r["refused"]) for r in rows) == [
        (1, trusted.module.address, None), (2, other.module.address, "drop_untrusted")]
    assert _counters(err, name)["drop_untrusted"] == 1
