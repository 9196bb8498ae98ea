"""A live view that cannot keep up never holds a bridge's stop (issue 38, item 5).

The live view's server is a child process the gateway feeds through a pipe. Flooded by viewers (thousands
of WebSocket connections, each costing its threads a log line and its main thread the GIL) it stops reading
that pipe for seconds, and a stop of the bridge used to wait for it: for the pump stuck writing, then for
the server's counters, then for its exit (a bridge ignored SIGINT for 15 s). Now the server gets 1 s, then
is ended. Both attacks here are real: a server frozen outright (SIGSTOP) while traffic fills its pipe, and
5,000 WebSocket connections opened and dropped while a robot talks.
"""

from __future__ import annotations

import base64
import contextlib
import os
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from peers import PtyPeer, start_vstig, wait_for
from ports import free_port

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing

pytest.importorskip("foxglove", reason="needs the live extra (`make test` installs every extra)")

STOP_S = 2.0


class Bridge:
    """`vstig bridge` on a pty radio with `--foxglove`, its robot writing 2,000 messages a second."""

    def __init__(self) -> None:
        self.radio = PtyPeer()
        os.set_blocking(self.radio.master, False)  # the robot never waits on a bridge that is gone
        self.port = free_port()
        self.process = start_vstig("bridge", f"serial:{self.radio.path}?framing=cobs8", "--robot-id", "1",
                                   "--foxglove", str(self.port))
        self.lines: list[str] = []
        stream = self.process.stderr
        threading.Thread(target=lambda: self.lines.extend(stream or ()), daemon=True).start()
        wait_for(lambda: any("live view:" in line for line in self.lines) or self.process.poll() is not None, 60)
        assert self.process.poll() is None, self.lines
        self._stop = threading.Event()
        self._robot = threading.Thread(target=self._talk, daemon=True)
        self._robot.start()

    def _talk(self) -> None:
        cobs, value = make_serial_framing("cobs8"), 0
        while not self._stop.is_set():
            value = value % 0xFFFF + 1
            with contextlib.suppress(BlockingIOError):
                self.radio.write(b"".join(unit for key in range(20)
                                          for unit in cobs.encode(Message(Op.PUT, key, value, value, 7))))
            self.radio.read(0)
            time.sleep(0.01)

    def server_pid(self) -> int:
        children = Path(f"/proc/{self.process.pid}/task/{self.process.pid}/children").read_text().split()
        (pid,) = children
        return int(pid)

    def interrupt(self) -> tuple[int, float]:
        started = time.monotonic()
        self.process.send_signal(signal.SIGINT)
        try:
            code = self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise AssertionError("the bridge ignored SIGINT for 30 s") from None
        return code, time.monotonic() - started

    def close(self) -> None:
        self._stop.set()
        self._robot.join(timeout=5)
        self.radio.close()


@pytest.fixture
def bridge() -> Iterator[Bridge]:
    made = Bridge()
    yield made
    made.close()


def test_a_frozen_live_view_server_does_not_hold_the_stop(bridge: Bridge) -> None:
    server = bridge.server_pid()
    os.kill(server, signal.SIGSTOP)  # reads nothing more: the traffic fills its pipe within a second
    try:
        time.sleep(1.5)
        code, took = bridge.interrupt()
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(server, signal.SIGCONT)
    assert code == 0 and took <= STOP_S, (code, took, "".join(bridge.lines))
    assert any("live view: its server did not end within 1 s" in line for line in bridge.lines), bridge.lines
    assert any(line.startswith("engine: ") for line in bridge.lines)  # the counters, printed
    with pytest.raises(ProcessLookupError):  # it was ended, not left behind
        os.kill(server, 0)


def _upgrade(port: int) -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    return (f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n"
            "\r\n").encode()


def test_five_thousand_viewers_coming_and_going_do_not_hold_the_stop(bridge: Bridge) -> None:
    done = threading.Event()
    opened = [0]

    def flood(count: int) -> None:
        for _ in range(count):
            if done.is_set():
                return
            try:
                with socket.create_connection(("127.0.0.1", bridge.port), timeout=5) as viewer:
                    viewer.sendall(_upgrade(bridge.port))
                    opened[0] += 1
            except OSError:
                pass

    floods = [threading.Thread(target=flood, args=(1250,), daemon=True) for _ in range(4)]
    for thread in floods:
        thread.start()
    wait_for(lambda: opened[0] >= 2500 or not any(t.is_alive() for t in floods), 60)
    try:
        code, took = bridge.interrupt()  # mid-flood
    finally:
        done.set()
        for thread in floods:
            thread.join(timeout=10)
    assert code == 0 and took <= STOP_S, (code, took, "".join(bridge.lines[-20:]))
    assert any(line.startswith("engine: ") for line in bridge.lines)
