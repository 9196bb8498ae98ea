"""BlabbermouthTransport against real TCP robots on 127.0.0.1: relay, own frames, hang-ups, bad addresses."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

import pytest

from vstig_hw.links import parse
from vstig_hw.links.blabbermouth import BlabbermouthSpec
from vstig_hw.transports.base import TransportError
from vstig_hw.transports.blabbermouth import BlabbermouthTransport

SIZE = 16


class FakeRobot:
    """A robot's TCP side: listens on an ephemeral loopback port, accepts the relay once."""

    def __init__(self) -> None:
        self.server = socket.socket()
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(1)
        self.port = self.server.getsockname()[1]
        self.conn: socket.socket | None = None

    def accept(self) -> None:
        self.server.settimeout(10)
        self.conn, _ = self.server.accept()
        self.conn.settimeout(0.05)

    def read(self) -> bytes:
        assert self.conn is not None
        try:
            return self.conn.recv(65536)
        except TimeoutError:
            return b""

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.server.close()


def _until(done: Callable[[], bool], what: str, deadline: float = 10.0) -> None:
    end = time.monotonic() + deadline
    while not done():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.01)


def _frame(robot: int, fill: int) -> bytes:
    return robot.to_bytes(2, "little") + bytes([fill]) * (SIZE - 2)


def test_relays_every_frame_to_the_others_and_sends_ours_to_all() -> None:
    robots = [FakeRobot() for _ in range(3)]
    transport = BlabbermouthTransport([("127.0.0.1", r.port) for r in robots], SIZE, connect_timeout=5)
    try:
        transport.open()
        for robot in robots:
            robot.accept()
        assert robots[0].conn is not None
        robots[0].conn.sendall(_frame(5, 0xAA)[:7])  # a frame in two pieces is still one frame
        robots[0].conn.sendall(_frame(5, 0xAA)[7:])
        got: dict[int, bytes] = {1: b"", 2: b""}

        def relayed() -> bool:
            for index in got:
                got[index] += robots[index].read()
            return all(len(data) >= SIZE for data in got.values())

        _until(relayed, "the relay")
        assert got == {1: _frame(5, 0xAA), 2: _frame(5, 0xAA)}
        assert robots[0].read() == b""  # never echoed to its sender
        frames: list[bytes] = []
        _until(lambda: bool(frames.extend(transport.read(0.05)) or frames), "the frame handed to read")
        assert frames == [_frame(5, 0xAA)]
        transport.write(_frame(200, 0x01) * 2)
        for robot in robots:
            received = b""
            end = time.monotonic() + 10
            while len(received) < 2 * SIZE and time.monotonic() < end:
                received += robot.read()
            assert received == _frame(200, 0x01) * 2
        with pytest.raises(ValueError, match="whole 16-byte frames"):
            transport.write(b"\x00" * 5)
    finally:
        transport.close()
        for robot in robots:
            robot.close()
    assert transport.counters["relayed"] == 2 and transport.counters["tx"] == 2


def test_a_robot_that_hangs_up_is_counted_and_dialled_again() -> None:
    robot = FakeRobot()
    transport = BlabbermouthTransport([("127.0.0.1", robot.port)], SIZE, connect_timeout=5)
    try:
        transport.open()
        robot.accept()
        assert robot.conn is not None
        robot.conn.close()
        robot.conn = None
        _until(lambda: transport.counters["robot_lost"] == 1, "the hang-up")
        assert not transport.connected
        transport.read(0.01)  # the redial happens in read, as the gateway loop calls it
        robot.accept()
        _until(lambda: (transport.read(0.01), transport.counters["reconnects"])[1] == 1, "the redial")
        assert transport.connected
    finally:
        transport.close()
        robot.close()


def test_a_robot_that_is_not_there_is_named() -> None:
    spare = socket.socket()
    spare.bind(("127.0.0.1", 0))
    port = spare.getsockname()[1]
    spare.close()  # nothing listens there now
    transport = BlabbermouthTransport([("127.0.0.1", port)], SIZE, connect_timeout=2)
    with pytest.raises(TransportError, match=f"127.0.0.1:{port}"):
        transport.open()


@pytest.mark.parametrize(("spec", "says"), [
    ("blabbermouth:10.0.0.1?size=64", "both needed"),
    ("blabbermouth:10.0.0.1?deployment=x.toml", "both needed"),
    ("blabbermouth:10.0.0.1:99999?size=64&deployment=x.toml", "port"),
    ("blabbermouth:10.0.0.1?size=4&deployment=x.toml", "size"),
    ("blabbermouth:,10.0.0.1?size=64&deployment=x.toml", "robot address"),
    ("blabbermouth:10.0.0.1?size=64&deployment=x.toml&baud=9600", "unknown parameter"),
])
def test_bad_blabbermouth_specs_say_what_is_wrong(spec: str, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        parse(spec)


def test_a_blabbermouth_spec() -> None:
    spec = parse("blabbermouth:10.0.0.1,k2.lab:7000?size=64&deployment=lab.toml")
    assert spec == BlabbermouthSpec((("10.0.0.1", 24580), ("k2.lab", 7000)), 64, "lab.toml")


@pytest.mark.parametrize(("spec", "says"), [
    ("serial:/dev/ttyUSB0?framing=kilobot&dialect=bittybuzz", "needs deployment"),
    ("serial:/dev/ttyUSB0?framing=cobs8&dialect=bittybuzz&deployment=x.toml", "framing=kilobot"),
    ("serial:/dev/ttyUSB0?framing=kilobot&dialect=lua&deployment=x.toml", "dialect='lua'"),
    ("serial:/dev/ttyUSB0?framing=kilobot&dialect=buzz&deployment=x.toml", "XbeeMav's packets on XBee radios"),
    ("serial:/dev/ttyUSB0?framing=kilobot&deployment=x.toml", "goes with dialect"),
])
def test_bad_bittybuzz_specs_say_what_is_wrong(spec: str, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        parse(spec)


def test_a_bittybuzz_link_with_a_missing_deployment_names_the_file() -> None:
    spec = parse("kilobot-ohc:/dev/null?dialect=bittybuzz&deployment=/nonexistent/lab.toml")
    with pytest.raises(ValueError, match=r"/nonexistent/lab\.toml"):
        spec.build("ohc")


def test_a_robot_that_stops_reading_is_hung_up_on_and_the_others_frames_go_on() -> None:
    import threading

    robots = [FakeRobot() for _ in range(3)]
    robots[2].server.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # robot 2 reads nothing: fill it fast
    size = 4096  # big frames: the deaf robot's and the kernel's buffers fill within a few MB
    transport = BlabbermouthTransport([("127.0.0.1", r.port) for r in robots], size, connect_timeout=5,
                                      send_timeout=0.2)
    frames = [(5).to_bytes(2, "little") + bytes([i % 256]) * (size - 2) for i in range(4000)]  # 16 MB
    got = bytearray()
    try:
        transport.open()
        for robot in robots:
            robot.accept()
        sender, listener = robots[0].conn, robots[1]
        assert sender is not None
        sender.settimeout(10)  # while the relay waits on robot 2, robot 0's own sends wait too
        begun = time.monotonic()

        def read_robot_1() -> None:  # a robot that keeps reading, as a live one does
            while len(got) < len(frames) * size and time.monotonic() < begun + 20:
                got.extend(listener.read())

        reading = threading.Thread(target=read_robot_1, daemon=True)
        reading.start()
        sender.sendall(b"".join(frames))
        reading.join()
        took = time.monotonic() - begun
    finally:
        transport.close()
        for robot in robots:
            robot.close()
    assert bytes(got) == b"".join(frames)  # robot 1 got every frame, in order
    assert transport.counters["robot_stalled"] >= 1  # robot 2 was hung up on, not waited for
    assert took < 10, took
