"""Serial links through real ptys: every framing both ways, faults on the line, the device vanishing."""

from __future__ import annotations

import contextlib
import logging
import os
import random
import shutil
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from serial_robot import OhcReceiver, PtyRobot, decode_stream, encode_for, epuck_words, frame, message_bytes, poll

from vstig_hw import Message, Op
from vstig_hw.framing import TransmitOnlyError
from vstig_hw.links import Link, parse
from vstig_hw.links.serial import serial_link
from vstig_hw.transports.base import TransportError
from vstig_hw.transports.serial import SerialTransport

FAST_BACKOFF = {"backoff_initial": 0.02, "backoff_max": 0.2}


def random_messages(n: int, seed: int) -> list[Message]:
    rng = random.Random(seed)
    return [Message(Op(rng.getrandbits(1)), rng.getrandbits(15), rng.getrandbits(16), rng.getrandbits(16),
                    rng.randrange(100)) for _ in range(n)]


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    yield master, os.ttyname(slave)
    for fd in (master, slave):
        with contextlib.suppress(OSError):  # the test closed it on purpose
            os.close(fd)


def hear(link: Link[bytes], until: int, deadline_s: float = 10.0) -> list[Message]:
    heard: list[Message] = []

    def enough() -> bool:
        heard.extend(h.message for h in link.receive(0.05))
        return len(heard) >= until

    poll(enough, deadline_s, f"{until} messages on {link.name}")
    return heard


@pytest.mark.parametrize("framing", ["cobs8", "epuck4", "kilobot"])
def test_every_framing_round_trips_through_a_pty(pty: tuple[int, str], framing: str) -> None:
    master, path = pty
    robot = PtyRobot(master)
    link = serial_link(path, framing)
    try:
        to_robot = random_messages(150, seed=1)
        for msg in to_robot:
            link.send(msg)
        poll(lambda: len(decode_stream(framing, robot.snapshot())) >= len(to_robot), what="the robot's inbox")
        assert decode_stream(framing, robot.snapshot()) == to_robot

        from_robot = random_messages(150, seed=2)
        robot.send(b"".join(encode_for(framing, msg) for msg in from_robot))
        assert hear(link, len(from_robot)) == from_robot
        assert not +link.framing.drops
        assert link.stats()["in"] == len(from_robot) and link.stats()["out"] == len(to_robot)
    finally:
        link.close()
        robot.stop()


@pytest.mark.parametrize("framing", ["cobs8", "epuck4", "kilobot", "kilobot-ohc"])
def test_send_many_is_one_write_of_the_same_bytes(pty: tuple[int, str], framing: str) -> None:
    master, path = pty
    robot = PtyRobot(master)
    link = serial_link(path, framing)
    try:
        messages = random_messages(40, seed=3)
        expected = link.framing.preamble + b"".join(unit for msg in messages for unit in link.framing.encode(msg))
        link.send_many(messages)
        poll(lambda: len(robot.snapshot()) >= len(expected), what="the robot's inbox")
        assert bytes(robot.snapshot()) == expected
        assert link.transport.counters["tx"] == 1 and link.stats()["out"] == len(messages)
    finally:
        link.close()
        robot.stop()


def test_overhead_controller_packets_through_a_pty(pty: tuple[int, str]) -> None:
    master, path = pty
    robot = PtyRobot(master)
    link = serial_link(path, "kilobot-ohc")
    try:
        assert link.transport.settings["baudrate"] == 38400  # type: ignore[attr-defined]
        sent = [m for m in random_messages(60, seed=3) if 0x55 not in message_bytes(m)][:40]
        for msg in sent:
            link.send(msg)
        controller = OhcReceiver()
        poll(lambda: len(robot.snapshot()) >= 132 * len(sent), what="all controller packets")
        controller.feed(robot.snapshot())
        assert len(controller.packets) == len(sent)
        for packet, msg in zip(controller.packets, sent, strict=True):
            assert len(packet) == 132 and packet[0] == 0x55 and packet[1] == 6  # FORWARDMSGSINGLE
            assert packet[2:10] == message_bytes(msg) and packet[10:12] == bytes((0x01, 0x56))
            assert packet[12:131] == bytes(119)
        with pytest.raises(TransmitOnlyError, match="transmit-only"):
            link.framing.feed(b"\x55")
    finally:
        link.close()
        robot.stop()


def frames_of(framing: str, msg: Message) -> list[bytes]:
    return [frame(w) for w in epuck_words(msg)] if framing == "epuck4" else [encode_for(framing, msg)]


def _corrupt(encoded: list[bytes], rng: random.Random) -> tuple[bytes, list[str]]:
    """The frames as a noisy line delivers them, and which fault hit each."""
    out = bytearray()
    faults = []
    for data in encoded:
        f = bytearray(data)
        fault = rng.choice(["none", "none", "flip", "drop", "garbage", "truncate", "zeros"])
        at = rng.randrange(len(f))
        if fault == "flip":
            f[at] ^= rng.randrange(1, 256)
        elif fault == "drop":
            del f[at]
        elif fault == "garbage":
            f[at:at] = rng.randbytes(rng.choice([1, 5, 30, 90]))  # 90: longer than any frame
        elif fault == "truncate":
            f = f[:max(1, at)]
        elif fault == "zeros":
            f[at:at] = bytes(rng.randint(1, 8))
        out += f
        faults.append(fault)
    return bytes(out) + b"\x00", faults  # a last delimiter flushes whatever is still partial


@pytest.mark.parametrize("framing", ["cobs8", "kilobot", "epuck4"])
def test_faults_on_the_line_are_dropped_counted_and_survived(pty: tuple[int, str], framing: str) -> None:
    master, path = pty
    rng = random.Random(11)
    messages = random_messages(600, seed=4)
    frames = [f for m in messages for f in frames_of(framing, m)]  # an epuck4 message is 3 frames
    clean_tail = random_messages(20, seed=5)
    noisy, faults = _corrupt(frames, rng)
    stream = noisy + b"".join(encode_for(framing, m) for m in clean_tail)
    assert {"flip", "drop", "garbage", "truncate", "zeros"} <= set(faults)

    valid = {f[:-1] for f in frames} | {f[:-1] for m in clean_tail for f in frames_of(framing, m)}
    segments = stream.split(b"\x00")[:-1]  # complete frames only
    bad_segments = sum(1 for s in segments if s and s not in valid)
    assert bad_segments > 100

    robot = PtyRobot(master)
    link = serial_link(path, framing)
    try:
        robot.send(stream)
        heard: list[Message] = []

        def all_bytes_read() -> bool:
            heard.extend(h.message for h in link.receive(0.05))
            return link.transport.counters["rx_bytes"] >= len(stream)  # type: ignore[attr-defined]

        poll(all_bytes_read, what="the whole noisy stream")
        drops = link.framing.drops
        frame_drops = drops["cobs"] + drops["crc"] + drops["bad_length"] + drops["overlong"]
        assert frame_drops == bad_segments, drops
        assert heard[-len(clean_tail):] == clean_tail, "the stream must recover at the next intact frame"
        if framing == "epuck4":
            assert set(heard) <= set(messages) | set(clean_tail), "a wrong message was delivered"
        else:
            by_frame = {f[:-1]: m for m in messages for f in frames_of(framing, m)}
            by_frame.update((encode_for(framing, m)[:-1], m) for m in clean_tail)
            assert heard == [by_frame[s] for s in segments if s in by_frame]
    finally:
        link.close()
        robot.stop()


def test_reconnects_when_the_device_vanishes_and_returns(tmp_path: Path,
                                                         caplog: pytest.LogCaptureFixture) -> None:
    """A USB dongle pulled out and plugged back: the pty dies, a new one appears under the same name."""
    caplog.set_level(logging.WARNING, logger="vstig_hw.transports.serial")
    name = tmp_path / "ttyROBOT"
    master1, slave1 = os.openpty()
    os.symlink(os.ttyname(slave1), name)
    link = serial_link(str(name), "cobs8", transport_options=FAST_BACKOFF)
    os.close(slave1)  # now only the transport holds the device open
    robot1 = PtyRobot(master1)
    a, b, c, d = random_messages(4, seed=6)
    robot1.send(encode_for("cobs8", a))
    assert hear(link, 1) == [a]

    robot1.stop()
    os.close(master1)  # unplugged: the device node goes away too, so a pty that another
    gone = tmp_path / "gone"  # process opens meanwhile (and gets the same /dev/pts number) is not "our" dongle
    os.symlink(tmp_path / "no-such-device", gone)
    os.replace(gone, name)
    poll(lambda: not link.receive(0.02) and not link.transport.connected, what="the loss to be noticed")
    for _ in range(20):  # the gateway keeps polling; the loss is still reported only once
        link.receive(0.01)
    link.send(b)
    assert link.stats()["tx_dropped"] == 1

    master2, slave2 = os.openpty()  # plugged back in
    fresh = tmp_path / "fresh"
    os.symlink(os.ttyname(slave2), fresh)
    os.replace(fresh, name)
    robot2 = PtyRobot(master2)
    try:
        # pyserial flushes the input when it opens a port: the robot talks once the PC is back
        poll(lambda: not link.receive(0.02) and link.transport.connected, what="the reconnect")
        robot2.send(encode_for("cobs8", c))
        assert hear(link, 1) == [c]
        link.send(d)
        poll(lambda: decode_stream("cobs8", robot2.snapshot()) == [d], what="the robot to hear d")
        stats = link.stats()
        assert stats["disconnects"] == 1 and stats["reconnects"] == 1
        lost = [r for r in caplog.records if "lost" in r.getMessage()]
        back = [r for r in caplog.records if "back after" in r.getMessage()]
        assert len(lost) == 1 and len(back) == 1 and str(name) in lost[0].getMessage()
    finally:
        link.close()
        robot2.stop()
        os.close(master2)
        os.close(slave2)


def test_the_first_byte_after_every_open_is_a_delimiter(tmp_path: Path) -> None:
    """SPEC 6.0.3: 0x00 before the first frame after opening, so a robot that holds half a frame resyncs."""
    name = tmp_path / "ttyROBOT"
    master1, slave1 = os.openpty()
    os.symlink(os.ttyname(slave1), name)
    link = serial_link(str(name), "cobs8", transport_options=FAST_BACKOFF)
    os.close(slave1)
    robot1 = PtyRobot(master1)
    a, b, c = random_messages(3, seed=8)
    half_a_frame = encode_for("cobs8", c)[:5]  # what the robot's receiver held when we opened the port
    try:
        link.send(a)
        link.send(b)
        poll(lambda: len(robot1.snapshot()) >= 25, what="two frames")
        assert robot1.snapshot() == b"\0" + encode_for("cobs8", a) + encode_for("cobs8", b)  # one 0x00, first
        assert decode_stream("cobs8", half_a_frame + robot1.snapshot()) == [a, b]  # a survives the junk

        robot1.stop()
        os.close(master1)  # unplugged
        poll(lambda: not link.receive(0.02) and not link.transport.connected, what="the loss to be noticed")
        master2, slave2 = os.openpty()  # plugged back in
        fresh = tmp_path / "fresh"
        os.symlink(os.ttyname(slave2), fresh)
        os.replace(fresh, name)
        robot2 = PtyRobot(master2)
        poll(lambda: not link.receive(0.02) and link.transport.connected, what="the reconnect")
        link.send(c)
        poll(lambda: len(robot2.snapshot()) >= 13, what="the frame after the reconnect")
        assert robot2.snapshot() == b"\0" + encode_for("cobs8", c)
    finally:
        link.close()
    robot2.stop()
    os.close(master2)
    os.close(slave2)


def test_a_bittybuzz_kilobot_link_starts_with_a_delimiter_too(pty: tuple[int, str], tmp_path: Path) -> None:
    master, path = pty
    deployment = tmp_path / "kilobots.toml"
    deployment.write_text('[keys]\nx = { key = 1, type = "int16" }\n', encoding="utf-8")
    robot = PtyRobot(master)
    link = parse(f"serial:{path}?framing=kilobot&dialect=bittybuzz&deployment={deployment}").build("bbz")
    link.open()
    try:
        link.send(Message(Op.PUT, 1, 5, 1, 3))
        poll(lambda: robot.snapshot().count(0) >= 2, what="the frame")
        assert robot.snapshot()[:1] == b"\0" and robot.snapshot().count(0) == 2  # the preamble, then one frame
    finally:
        link.close()
        robot.stop()


def test_reconnects_to_a_socket_server_that_restarts() -> None:
    """socket:// (e.g. ser2net in front of a dongle): the server stops, comes back on the same port."""
    listener = socket.create_server(("127.0.0.1", 0), reuse_port=False)
    port = listener.getsockname()[1]
    m1, m2 = random_messages(2, seed=7)

    def serve_once(server: socket.socket, msg: Message, done: threading.Event) -> None:
        conn, _ = server.accept()
        heard = b""
        while b"\x00" not in heard:  # pyserial drops input that arrives while it opens: wait for the PC to speak
            heard += conn.recv(64)
        conn.sendall(encode_for("cobs8", msg))
        done.wait(10)
        conn.close()
        server.close()

    first_done = threading.Event()
    threading.Thread(target=serve_once, args=(listener, m1, first_done), daemon=True).start()
    link = serial_link(f"socket://127.0.0.1:{port}", "cobs8", transport_options=FAST_BACKOFF)
    try:
        link.send(m2)
        assert hear(link, 1) == [m1]
        first_done.set()  # the server goes away
        poll(lambda: not link.receive(0.02) and not link.transport.connected, what="the loss to be noticed")
        second = socket.create_server(("127.0.0.1", port))
        second_done = threading.Event()
        threading.Thread(target=serve_once, args=(second, m2, second_done), daemon=True).start()
        poll(lambda: not link.receive(0.02) and link.transport.connected, what="the reconnect")
        link.send(m1)
        assert hear(link, 1) == [m2]
        assert link.stats()["reconnects"] == 1
        second_done.set()
    finally:
        link.close()


def test_missing_device_is_one_clear_line() -> None:
    with pytest.raises(TransportError) as caught:
        SerialTransport("/dev/ttyNO_SUCH_DONGLE").open()
    text = str(caught.value)
    assert "/dev/ttyNO_SUCH_DONGLE" in text and "no such device" in text and "\n" not in text


def test_busy_port_is_one_clear_line(pty: tuple[int, str]) -> None:
    _, path = pty
    with SerialTransport(path), pytest.raises(TransportError, match=f"{path}: port busy"):
        SerialTransport(path).open()


def test_permission_denied_names_the_dialout_fix(pty: tuple[int, str]) -> None:
    _, path = pty
    os.chmod(path, 0)
    probe = (f"from vstig_hw.transports.serial import SerialTransport\n"
             f"SerialTransport({path!r}).open()\n")
    command = [sys.executable, "-c", probe]
    if os.geteuid() == 0:  # root ignores file modes: run the probe without the capability that allows it
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
                pytest.fail("setpriv (util-linux) is needed to test permission errors as root")
            pytest.skip("running as root without setpriv: cannot make the kernel deny access")
        command = [setpriv, "--bounding-set=-dac_override,-dac_read_search", *command]
    done = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode != 0
    assert "TransportError" in last and path in last and "permission denied" in last and "dialout" in last


def test_bad_line_settings_and_use_before_open_name_the_port(pty: tuple[int, str]) -> None:
    _, path = pty
    with pytest.raises(TransportError, match=f"serial port {path}: .*parity"):
        SerialTransport(path, parity="Q").open()
    with pytest.raises(TransportError, match="not open"):
        SerialTransport(path).read(0.01)


@pytest.mark.parametrize("spec", [
    "serial:spy://{port}?file={victim}",
    "serial:SPY://{port}?raw&fil%65={victim}&framing=epuck4",  # pyserial lower-cases the scheme, decodes the key
    "serial:spy://{port}?file={victim}?baud=9600",
    "kilobot-ohc:spy://{port}?file={victim}",
])
def test_a_pyserial_url_that_writes_a_file_is_refused_as_it_is_parsed(pty: tuple[int, str], tmp_path: Path,
                                                                      spec: str) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("a lab notebook")
    text = spec.format(port=pty[1], victim=victim)
    with pytest.raises(ValueError, match=r"pyserial's spy:// writes file=\.\.\., and a link never writes files"):
        parse(text)
    result = subprocess.run([sys.executable, "-m", "vstig_cli.main", "record", text, "-o", str(tmp_path / "r.cap"),
                             "--for", "0.5"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "spy:// writes file=" in result.stderr, result.stderr
    assert victim.read_text() == "a lab notebook" and not (tmp_path / "r.cap").exists()


def test_the_spy_handler_without_a_file_still_opens_the_port(pty: tuple[int, str]) -> None:
    master, path = pty
    link = parse(f"serial:spy://{path}?framing=cobs8").build()  # spy logs a hexdump to stderr
    robot = PtyRobot(master)
    link.open()
    try:
        sent = random_messages(3, seed=5)
        for msg in sent:
            robot.send(encode_for("cobs8", msg))
        assert hear(link, 3) == sent
    finally:
        link.close()
        robot.stop()
