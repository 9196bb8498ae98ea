"""A zenoh link told to connect where nobody answers names the endpoint: in put's and get's error, in one line of
sniff and bridge (which keep retrying, and find the peer once it is up), and in join's exception (issue 44).
A listening gateway whose one-shot client finished says nothing of a loss. Real Zenoh sessions on loopback."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
from peers import run_vstig, start_vstig
from ports import free_port

import vstig_hw
from vstig_hw.links import parse

pytest.importorskip("zenoh", reason="the zenoh extra is not installed")

NOBODY = "reached nobody at connect="


class Lines:
    """A running vstig's stderr, line by line as it comes."""

    def __init__(self, *args: str) -> None:
        self.process = start_vstig(*args)
        self.lines: list[str] = []
        stderr = self.process.stderr
        assert stderr is not None
        self._pump = threading.Thread(target=lambda: self.lines.extend(iter(stderr.readline, "")), daemon=True)
        self._pump.start()

    def stop(self) -> str:
        """SIGTERM, as Ctrl-C would; everything it said."""
        self.process.terminate()
        try:
            assert self.process.wait(timeout=10) == 0, "".join(self.lines)
        finally:
            if self.process.poll() is None:
                self.process.kill()
            self._pump.join(timeout=5)
        return "".join(self.lines)

    def wait_for(self, text: str, deadline: float = 20.0) -> str:
        end = time.monotonic() + deadline
        while time.monotonic() < end:
            found = [line for line in self.lines if text in line]
            if found:
                return found[0]
            assert self.process.poll() is None, f"vstig ended: {''.join(self.lines)}"
            time.sleep(0.05)
        raise AssertionError(f"no line with {text!r} in {''.join(self.lines)}")


@pytest.mark.parametrize("command", ["put", "get"])
def test_a_one_shot_command_names_the_socket_it_could_not_reach(tmp_path: Path, command: str) -> None:
    missing = tmp_path / "lab.sock"
    args = ["3", "1"] if command == "put" else ["3"]
    done = run_vstig(command, *args, "--on", f"zenoh:lab?connect=unixsock-stream/{missing}", "--wait", "1")
    assert done.returncode == 1 and "Traceback" not in done.stderr
    error = done.stderr.strip().splitlines()[-1]
    assert error.startswith("Error: ") and "no neighbour on zenoh-lab" in error
    assert f"zenoh-lab {NOBODY}unixsock-stream/{missing} (no such socket file)" in error, error


def test_a_file_that_is_not_a_socket_is_said_so(tmp_path: Path) -> None:
    plain = tmp_path / "lab.sock"
    plain.write_text("not a socket")
    done = run_vstig("get", "3", "--on", f"zenoh:lab?connect=unixsock-stream/{plain}", "--wait", "0.5")
    assert done.returncode == 1 and f"{NOBODY}unixsock-stream/{plain} (not a socket)" in done.stderr, done.stderr


@pytest.mark.parametrize("command", [["sniff"], ["bridge", "--robot-id", "7"]])
def test_a_long_running_command_says_it_once_and_finds_the_peer_once_up(command: list[str]) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lines = Lines(*command, f"zenoh:lab?connect={endpoint}")
    peer = None
    try:
        line = lines.wait_for(NOBODY)
        assert line.startswith(f"zenoh-lab: {NOBODY}{endpoint}: ") and "Zenoh keeps retrying" in line
        peer = parse(f"zenoh:lab?listen={endpoint}").build(robot_id=1)
        peer.open()  # the endpoint comes up: Zenoh's retry reaches it
        lines.wait_for("Zenoh peers reachable again", 30)
        assert sum(NOBODY in text for text in lines.lines) == 1  # one line, not one per retry
    finally:
        lines.stop()
        if peer is not None:
            peer.close()


def test_join_raises_naming_the_endpoint(tmp_path: Path) -> None:
    missing = tmp_path / "lab.sock"
    started = time.monotonic()
    with pytest.raises(vstig_hw.TransportError) as caught:
        vstig_hw.join(f"zenoh:lab?connect=unixsock-stream/{missing}", robot_id=3)
    assert str(caught.value).startswith(f"zenoh-lab {NOBODY}unixsock-stream/{missing} (no such socket file)")
    assert time.monotonic() - started < 6  # the link's 3 s wait, not forever


def test_join_with_a_client_whose_router_is_down_raises_too() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with pytest.raises(vstig_hw.TransportError, match=f"zenoh-lab {NOBODY}{endpoint}"):
        vstig_hw.join(f"zenoh:lab?mode=client&connect={endpoint}", robot_id=3)


def test_a_listening_gateway_says_nothing_of_a_loss_when_a_put_client_finishes(tmp_path: Path) -> None:
    socket_path = tmp_path / "lab.sock"
    lines = Lines("bridge", f"zenoh:lab?listen=unixsock-stream/{socket_path}", "--robot-id", "1")
    try:
        lines.wait_for("listening on unixsock-stream/")
        put = run_vstig("put", "3", "1", "--on", f"zenoh:lab?connect=unixsock-stream/{socket_path}",
                        "--robot-id", "9", "--learn", "2.5")  # connected long enough for the gateway to see it
        assert put.returncode == 0, put.stderr
        time.sleep(2.5)  # the gateway looks at its peers once a second
    finally:
        said = lines.stop()
    assert "lost every Zenoh peer" not in said and "lost=" not in said, said
    assert "zenoh-lab: " in said and "in=" in said  # its summary was printed: it ran to the end
