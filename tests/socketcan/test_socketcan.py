"""Real SocketCAN through python-can's `socketcan` interface, with can-utils as independent peers.

Needs vcan0 (classic) and vcan1 (CAN FD, MTU 72). `test_in_uml.py` boots User-Mode
Linux to provide them and runs this module inside it; on a host that already has
them, this module runs directly.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
from can_vectors import FrameVector, load

from vstig_hw import Message, Op, encode
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.links import Link
from vstig_hw.links.can import can_link
from vstig_hw.transports.base import TransportError

IN_UML = os.environ.get("VSTIG_IN_UML") == "1"
CLASSIC, FD = "vcan0", "vcan1"


def _missing() -> str | None:
    for dev in (CLASSIC, FD):
        if not Path(f"/sys/class/net/{dev}").exists():
            return f"no {dev} here"
    if Path(f"/sys/class/net/{FD}/mtu").read_text().strip() != "72":
        return f"{FD} is not CAN FD capable (`ip link set {FD} mtu 72`)"
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
    except OSError as exc:
        return f"this kernel has no SocketCAN ({exc})"
    for tool in ("cansend", "candump"):
        if shutil.which(tool) is None:
            return f"can-utils' {tool} is missing"
    return None


_REASON = _missing()
if _REASON and IN_UML:
    raise RuntimeError(f"the UML guest should provide SocketCAN, but: {_REASON}")
if _REASON:
    pytest.skip(f"{_REASON}: tests/socketcan/test_in_uml.py runs this module inside User-Mode Linux",
                allow_module_level=True)

pytestmark = pytest.mark.socketcan
VECTORS = load()
DEADLINE_S = 30.0  # generous: system calls inside UML are about 10x slower
SYNC = "5A5#53594E43"  # "SYNC" under base 0x400, which no vector uses: proves candump is listening
SENTINEL = Message(Op.PUT, 0x7ABC, 0, 1, 0x42)  # sent after each vector: once it arrives, the vector has too


def _channel(vector: FrameVector) -> str:
    return FD if vector.frame.is_fd else CLASSIC


def _cansend(channel: str, frame: str) -> None:
    subprocess.run(["cansend", channel, frame], check=True, timeout=DEADLINE_S)


def _id_text(scheme: CanIdScheme, ident: int) -> str:
    return f"{ident:08X}" if scheme.extended else f"{ident:03X}"


def _sentinel_frame(scheme: CanIdScheme) -> str:
    return f"{_id_text(scheme, scheme.can_id(Op.PUT, SENTINEL.robot))}#{encode(SENTINEL).hex().upper()}"


def _link(vector: FrameVector, sender: int) -> Link[can.Message]:
    scheme = vector.scheme
    link = can_link("socketcan", _channel(vector), robot_id=sender, fd=vector.frame.is_fd, id_base=scheme.base,
                    extended=scheme.extended, stigmergy=scheme.stigmergy)
    link.open()
    return link


def test_cansend_frames_decode_to_the_vector_messages() -> None:
    for vector in VECTORS:
        link = _link(vector, sender=1)
        try:
            _cansend(_channel(vector), vector.cansend)
            _cansend(_channel(vector), _sentinel_frame(vector.scheme))
            heard = []
            deadline = time.monotonic() + DEADLINE_S
            while SENTINEL not in [h.message for h in heard] and time.monotonic() < deadline:
                heard.extend(link.receive(0.1))
            assert heard and heard[-1].message == SENTINEL, f"{vector.name}: the sentinel never arrived"
            before = heard[:-1]
            assert [h.message for h in before] == vector.messages, vector.name
            assert all(h.sender == vector.sender for h in before), vector.name
            drops = dict(link.framing.drops)
            if vector.drop == "unknown_id":  # the kernel filter kept it from us: only the sentinel was read
                assert drops == {} and link.transport.counters["rx"] == 1, vector.name
            else:
                assert drops == ({} if vector.drop is None else {vector.drop: 1}), vector.name
        finally:
            link.close()


def _without_fdf(frame: str) -> str:
    """ID##<flags>DATA with the kernel's CANFD_FDF flag (0x4, set on every FD frame since Linux 6.0) cleared."""
    ident, sep, rest = frame.partition("##")
    return f"{ident}##{int(rest[0], 16) & ~0x4:X}{rest[1:]}" if sep else frame


class Candump:
    """can-utils' candump as a subprocess whose output lines we can wait for."""

    def __init__(self, *args: str, cwd: Path | None = None) -> None:
        self.proc = subprocess.Popen(["candump", *args], stdout=subprocess.PIPE, text=True, cwd=cwd)
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))

    def frames(self) -> list[tuple[str, str]]:
        """(interface, ID#DATA) of every line so far, from `-L` output, FD flags as cansend writes them."""
        while True:
            try:
                self.seen.append(self.lines.get_nowait())
            except queue.Empty:
                break
        return [(fields[1], _without_fdf(fields[2])) for fields in (line.split() for line in self.seen)
                if len(fields) == 3]

    def wait_for(self, channel: str, frame: str, resend: bool = False) -> None:
        deadline = time.monotonic() + DEADLINE_S
        while (channel, frame) not in self.frames():
            assert time.monotonic() < deadline, f"candump never showed {channel} {frame}: {self.seen}"
            if resend:  # candump may not have bound its socket yet: send again until it shows
                _cansend(channel, frame)
            with contextlib.suppress(queue.Empty):
                self.seen.append(self.lines.get(timeout=0.2))

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(timeout=DEADLINE_S)


@pytest.fixture
def candump_ready(tmp_path: Path) -> Iterator[Candump]:
    """candump -l (a log file in tmp_path) -s 0 -L (the same frames on stdout), listening on both buses."""
    dump = Candump("-l", "-s", "0", "-L", CLASSIC, FD, cwd=tmp_path)
    try:
        for channel in (CLASSIC, FD):
            dump.wait_for(channel, SYNC, resend=True)
        yield dump
    finally:
        if dump.proc.poll() is None:
            dump.stop()


def test_fd_flags_digit_is_written_1_and_logged_5_as_spec_says(candump_ready: Candump) -> None:
    """SPEC 6.5.5 'FD notation': cansend's `607##1...` is the frame candump -L prints as `607##5...`."""
    data = "0001000A000100070002001400010007"
    _cansend(FD, f"607##1{data}")
    candump_ready.wait_for(FD, f"607##1{data}")
    raw = [line.split()[2] for line in candump_ready.seen if len(line.split()) == 3 and line.split()[1] == FD]
    assert f"607##5{data}" in raw, raw


def test_our_frames_show_up_in_candump_with_the_spec_ids_and_bytes(candump_ready: Candump) -> None:
    expected = []
    for vector in VECTORS:
        if vector.drop is None:
            assert vector.sender is not None
            link = _link(vector, sender=vector.sender)
            try:
                link.send_many(vector.messages)
                assert link.transport.counters["tx"] == 1
            finally:
                link.close()
            expected.append((_channel(vector), vector.cansend))
            candump_ready.wait_for(*expected[-1])
    ours = [f for f in candump_ready.frames() if f[1] != SYNC]
    assert ours == expected


def test_a_candump_log_file_decodes_through_our_framing(candump_ready: Candump, tmp_path: Path) -> None:
    for vector in VECTORS:
        _cansend(_channel(vector), vector.cansend)
    candump_ready.wait_for(_channel(VECTORS[-1]), VECTORS[-1].cansend)
    candump_ready.stop()
    (log_file,) = tmp_path.glob("candump-*.log")
    frames = [f for f in can.LogReader(log_file) if f.data != b"SYNC"]
    assert len(frames) == len(VECTORS)
    for vector, frame in zip(VECTORS, frames, strict=True):
        assert frame.channel == _channel(vector)
        framing = CanFraming(vector.scheme, sender=1, fd=True)
        assert framing.feed(frame) == vector.messages, vector.name
        # no kernel filter here: foreign IDs reach the framing and are counted as unknown_id
        assert dict(framing.drops) == ({} if vector.drop is None else {vector.drop: 1}), vector.name


def test_missing_channel_is_one_clear_line() -> None:
    with pytest.raises(TransportError) as caught:
        can_link("socketcan", "vcan9", robot_id=1).open()
    assert str(caught.value) == "no such CAN interface vcan9: create it with `ip link add vcan9 type vcan`"


def _ip(*args: str) -> None:
    subprocess.run(["ip", "link", *args], check=True, timeout=DEADLINE_S, capture_output=True)


@pytest.mark.skipif(os.geteuid() != 0 and not IN_UML, reason="creating and deleting vcan interfaces needs root")
def test_a_deleted_interface_is_reported_and_reconnected_when_it_returns() -> None:
    _ip("add", "dev", "vcan2", "type", "vcan")
    _ip("set", "up", "vcan2")
    link = can_link("socketcan", "vcan2", robot_id=1)
    link.open()
    try:
        _ip("delete", "vcan2")  # the adapter is unplugged
        deadline = time.monotonic() + DEADLINE_S
        while link.transport.connected and time.monotonic() < deadline:
            link.receive(0.1)
        assert not link.transport.connected and link.transport.counters["lost"] == 1
        link.send(SENTINEL)  # dropped and counted while the device is gone
        assert link.transport.counters["tx_dropped"] == 1
        _ip("add", "dev", "vcan2", "type", "vcan")
        _ip("set", "up", "vcan2")
        heard: list[Message] = []
        deadline = time.monotonic() + DEADLINE_S
        while not heard and time.monotonic() < deadline:
            if link.transport.connected:
                _cansend("vcan2", "602#0001000500010002")
            heard = [h.message for h in link.receive(0.1)]
        assert heard == [Message(Op.PUT, 1, 5, 1, 2)]
        assert link.transport.counters["reconnects"] == 1
    finally:
        link.close()
        subprocess.run(["ip", "link", "delete", "vcan2"], check=False, capture_output=True)


def test_frames_the_kernel_drops_are_counted_not_lost_silently() -> None:
    from vstig_hw.transports.can import CanTransport

    burst = 500
    transport = CanTransport("socketcan", CLASSIC)
    transport.open()
    try:
        assert transport.bus is not None
        # The smallest receive queue the kernel allows: a burst we do not read overflows it.
        transport.bus.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1)
        got: list[can.Message] = []
        with can.Bus(interface="socketcan", channel=CLASSIC, receive_own_messages=False) as sender:
            for i in range(burst):
                sender.send(can.Message(arbitration_id=0x123, data=i.to_bytes(2, "big"), is_extended_id=False),
                            timeout=5)
            while frames := transport.read(0.5):
                got += frames
            # The count rides on the next frame received: send one more and read it.
            sender.send(can.Message(arbitration_id=0x124, data=b"end", is_extended_id=False), timeout=5)
            deadline = time.monotonic() + 10
            while not (got and got[-1].arbitration_id == 0x124) and time.monotonic() < deadline:
                got += transport.read(0.5)
    finally:
        transport.close()
    assert got[-1].arbitration_id == 0x124 and got[-1].timestamp > 1e9  # python-can's own stamps still
    dropped = transport.counters["kernel_dropped"]
    assert dropped > 0 and len(got) - 1 + dropped == burst, (len(got), dropped)
    assert transport.counters["rx"] == len(got)


def test_record_on_a_bursting_bus_loses_nothing_silently(tmp_path: Path) -> None:
    vstig = str(Path(sys.executable).with_name("vstig"))
    out = tmp_path / "burst.log"
    record = subprocess.Popen([vstig, "record", f"can:socketcan:{CLASSIC}", "-o", str(out)],
                              stderr=subprocess.PIPE, text=True)
    try:
        assert record.stderr is not None and record.stderr.readline().startswith("recording")
        subprocess.run(["cangen", CLASSIC, "-g", "0", "-n", "5000", "-I", "601", "-L", "8", "-D", "i", "-p", "100"],
                       check=True, timeout=120)
        # Stop only once the recorder has read its queue dry: frames still queued at a stop are not a drop.
        sizes = [-1]
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (len(sizes) < 3 or sizes[-1] != sizes[-3]):
            time.sleep(0.5)
            sizes.append(out.stat().st_size if out.exists() else 0)
    finally:
        record.send_signal(signal.SIGINT)
        _, summary = record.communicate(timeout=300)  # a guest on a loaded machine writes slowly
    assert record.returncode == 0, summary
    recorded = sum(1 for line in out.read_text().splitlines() if line.strip())
    dropped = sum(int(n) for n in re.findall(r"(?:kernel_dropped|interface_dropped|unread_at_close)=(\d+)", summary))
    assert recorded + dropped == 5000, summary  # every frame is in the file or counted as dropped


def test_frames_still_queued_at_close_are_counted_not_lost_silently() -> None:
    from vstig_hw.transports.can import CanTransport

    transport = CanTransport("socketcan", CLASSIC)
    transport.open()
    assert transport.read(0.1) == []  # a reader (a send-only link's unread frames are not a loss)
    with can.Bus(interface="socketcan", channel=CLASSIC) as sender:
        for i in range(50):
            sender.send(can.Message(arbitration_id=0x125, data=bytes([i]), is_extended_id=False), timeout=5)
        time.sleep(0.5)
    transport.close()  # not read since: all 50 are still queued, and go with the socket
    assert transport.counters["unread_at_close"] == 50, transport.counters


def test_a_classic_link_on_an_fd_bus_hears_fd_frames() -> None:
    link = can_link("socketcan", FD, robot_id=1)  # classic: no fd=1
    link.open()
    try:
        # Two PUTs in one 16-byte CAN FD frame from node 7 (cansend's ## marks FD).
        _cansend(FD, "607##0" + "0003000a00020007" + "0004000b00020007")
        heard = []
        deadline = time.monotonic() + DEADLINE_S
        while len(heard) < 2 and time.monotonic() < deadline:
            heard += link.receive(0.2)
    finally:
        link.close()
    assert [(h.message.key, h.message.value) for h in heard] == [(3, 10), (4, 11)]


def _read_for(link: Link[can.Message], seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        link.receive(0.05)


def _heard_again(link: Link[can.Message], channel: str) -> None:
    """Send from can-utils until the link hears it: the interface is back and the link reopened."""
    deadline = time.monotonic() + DEADLINE_S
    while time.monotonic() < deadline:
        _cansend(channel, "602#0001000500010002")
        if [h.message for h in link.receive(0.1)] == [Message(Op.PUT, 1, 5, 1, 2)]:
            return
    raise AssertionError(f"never heard {channel} again")


@pytest.mark.skipif(os.geteuid() != 0 and not IN_UML, reason="taking vcan interfaces down needs root")
def test_an_interface_that_is_down_is_one_outage_logged_once_not_a_reconnect_storm(
        caplog: pytest.LogCaptureFixture) -> None:
    # SocketCAN binds to an interface that is down, then fails the first read with ENETDOWN:
    # each reopen "succeeds", and must not count (or log) as the device coming back.
    caplog.set_level(logging.DEBUG, logger="vstig_hw.transports.can")
    _ip("add", "dev", "vcan4", "type", "vcan")
    _ip("set", "up", "vcan4")
    link = can_link("socketcan", "vcan4", robot_id=1)
    link.open()
    try:
        _ip("set", "down", "vcan4")
        _read_for(link, 1.5)
        _ip("set", "up", "vcan4")
        _heard_again(link, "vcan4")
        _ip("delete", "vcan4")  # then the adapter is unplugged and plugged back in
        _read_for(link, 1.5)
        _ip("add", "dev", "vcan4", "type", "vcan")
        _ip("set", "up", "vcan4")
        _heard_again(link, "vcan4")
    finally:
        link.close()
        subprocess.run(["ip", "link", "delete", "vcan4"], check=False, capture_output=True)
    counters = link.transport.counters
    assert (counters["lost"], counters["reconnects"]) == (2, 2), counters
    said = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert sum("CAN device lost" in line for line in said) == 2, said
    assert sum("CAN device back" in line for line in said) == 2, said
    # Backoff 0.1 s doubling to 2 s: at most 4 tries in each 1.5 s outage (a fixed 0.1 s made ~15);
    # a loaded machine only makes fewer.
    retries = [r.getMessage() for r in caplog.records if "still lost" in r.getMessage()]
    assert len(retries) <= 8, retries


@pytest.mark.skipif(os.geteuid() != 0 and not IN_UML, reason="taking vcan interfaces down needs root")
def test_bridge_says_once_per_unplug_that_the_interface_is_lost_and_once_that_it_is_back() -> None:
    # The field report: `ip link set vcan0 down` for a second, then delete and re-create it:
    # 15 "CAN device lost" lines and reconnects=15 for two unplugs.
    _ip("add", "dev", "vcan5", "type", "vcan")
    _ip("set", "up", "vcan5")
    vstig = str(Path(sys.executable).with_name("vstig"))
    bridge = subprocess.Popen([vstig, "bridge", "can:socketcan:vcan5", "--robot-id", "5"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    said: queue.Queue[str] = queue.Queue()
    lines: list[str] = []

    def pump() -> None:
        assert bridge.stderr is not None
        for line in bridge.stderr:
            said.put(line.rstrip("\n"))

    def wait_for_line(text: str) -> None:
        deadline = time.monotonic() + DEADLINE_S
        while not any(text in line for line in lines):
            assert time.monotonic() < deadline, f"bridge never said {text!r}: {lines}"
            with contextlib.suppress(queue.Empty):
                lines.append(said.get(timeout=0.2))

    threading.Thread(target=pump, daemon=True).start()
    try:
        wait_for_line("bridging")
        _ip("set", "down", "vcan5")
        wait_for_line("CAN device lost")
        time.sleep(1.5)
        _ip("set", "up", "vcan5")
        wait_for_line("CAN device back")
        _ip("delete", "vcan5")
        time.sleep(1.5)
        _ip("add", "dev", "vcan5", "type", "vcan")
        _ip("set", "up", "vcan5")
        deadline = time.monotonic() + DEADLINE_S
        while sum("CAN device back" in line for line in lines) < 2:
            assert time.monotonic() < deadline, f"the bridge never came back twice: {lines}"
            with contextlib.suppress(queue.Empty):
                lines.append(said.get(timeout=0.2))
    finally:
        bridge.send_signal(signal.SIGINT)
        bridge.wait(timeout=DEADLINE_S)
        subprocess.run(["ip", "link", "delete", "vcan5"], check=False, capture_output=True)
    time.sleep(0.2)
    while not said.empty():
        lines.append(said.get_nowait())
    assert bridge.returncode == 0, lines
    assert sum("CAN device lost" in line for line in lines) == 2, lines
    assert sum("CAN device back" in line for line in lines) == 2, lines
    (counters,) = [line for line in lines if line.startswith("vcan5: ")]
    assert " lost=2 " in f" {counters} " and " reconnects=2 " in f" {counters} ", counters


def test_a_gateway_writes_records_straight_to_the_socket_on_a_link_that_requires_tags() -> None:
    """auth=require on CAN FD (SPEC.md 10.5, 10.6): a robot's honest record is stored, its forged copy refused; the
    gateway's own write and its answer to a GET leave as 20-byte records from the compiled outlet itself (its writer
    never handed a frame), each verified with the writers' keys by a peer on the bus."""
    from vstig_hw.auth import SwarmKeys, Tagged
    from vstig_hw.gateway import Node
    from vstig_hw.links.assemble import assemble_links
    from vstig_hw.native import native

    keys = SwarmKeys(bytes(range(0x20, 0x40)))
    robot = CanFraming(CanIdScheme(), sender=5, fd=True)
    honest = keys.tag(Message(Op.PUT, 1, 77, 3, 5), 0)
    forged = Tagged(Message(Op.PUT, 2, 66, 3, 5), 0, bytes(8))
    links = assemble_links([f"can:socketcan:{FD}?fd=1&auth=require"], 200)
    handed: list[int] = []
    with can.Bus(interface="socketcan", channel=FD, fd=True) as peer, \
            Node(links, 200, budget=None, swarm_keys=keys) as node:
        assert node.compiled == (native is not None)  # the pure pass (VSTIG_PURE=1) runs it on the Python path
        for outlet in node.outlets:
            submit = outlet.writer.submit
            outlet.writer.submit = lambda units, count, submit=submit: (handed.append(count), submit(units, count))
        for frame in robot.encode_tagged([honest, forged]):
            peer.send(frame)
        deadline = time.monotonic() + DEADLINE_S
        while node.entry(1) is None and time.monotonic() < deadline:
            time.sleep(0.05)
        node.put(3, 9)
        for frame in robot.encode(Message(Op.GET, 1, 0, 0, 5)):
            peer.send(frame)
        heard: list[Tagged | None] = []
        listener = CanFraming(CanIdScheme(), sender=6, fd=True)
        while len(heard) < 2 and time.monotonic() < deadline:
            frame = peer.recv(0.2)
            if frame is not None and listener.sender_of(frame) == 200:  # sent by the gateway
                heard += [record for _, record in listener.feed_tagged(frame)]
        stored = (node.entry(1), node.entry(2))
        refused = node.stats()[links[0].name]["drop_bad_tag"]
    assert stored[0] is not None and stored[1] is None and refused == 1
    assert (handed == []) == node.compiled  # the compiled outlet writes itself; the Python one through its writer
    assert [record is not None and keys.verify(record) for record in heard] == [True, True]
    assert sorted((r.message.key, r.message.robot) for r in heard if r is not None) == [(1, 5), (3, 200)]
