"""An output that is not a file (a FIFO, a terminal, a socket) is refused before any work (issue 38, item 5).

A named pipe holds its writer in open() until a reader comes, and then in every write it is slow to take:
`record -o FIFO --for 2` was still blocked in open() ten minutes after a SIGINT. Each command is a real
`vstig` process here, given a real FIFO (and a socket); it must end at once with one line naming the path
and exit 2, having run nothing. Devices that answer at once (/dev/null, /dev/full) stay valid sinks.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest
from peers import PtyPeer, run_vstig

LOG = "".join(f"(1700000000.{i}00000) can0 60{i}#000300{i:02X}00010001\n" for i in range(1, 4))


@pytest.fixture
def radio() -> Iterator[PtyPeer]:
    peer = PtyPeer()
    yield peer
    peer.close()


COMMANDS = {
    "record": ["record", "{radio}", "-o", "{out}", "--for", "2"],
    "record-overwrite": ["record", "{radio}", "-o", "{out}", "--for", "2", "--overwrite"],
    "record-append": ["record", "{radio}", "-o", "{out}", "--for", "2", "--append"],
    "decode": ["decode", "{log}", "--format", "mcap", "-o", "{out}"],
    "analyze": ["analyze", "{log}", "--plot", "{out}"],
    "sim-capture": ["sim", "--topology", "line", "--robots", "5", "--runs", "1", "--workers", "1", "--capture",
                    "{out}"],
    "sim-snapshot": ["sim", "--topology", "motion", "--robots", "10", "--density", "1", "--snapshot", "{out}"],
}


@pytest.mark.parametrize("command", list(COMMANDS), ids=list(COMMANDS))
def test_a_fifo_output_is_refused_before_any_work(command: str, tmp_path: Path, radio: PtyPeer) -> None:
    out = tmp_path / "out.fifo"
    os.mkfifo(out)
    log = tmp_path / "swarm.log"
    log.write_text(LOG)
    args = [a.replace("{out}", str(out)).replace("{log}", str(log)).replace("{radio}", f"serial:{radio.path}")
            for a in COMMANDS[command]]
    done = run_vstig(*args, timeout=60)  # before, record waited in open() for a reader, for ever
    assert done.returncode == 2, done.stderr
    assert f"{out} is a named pipe (FIFO): vstig writes its outputs into regular files only" in done.stderr
    assert "Traceback" not in done.stderr and done.stderr.count("Error:") == 1, done.stderr


def test_a_socket_output_is_refused(tmp_path: Path, radio: PtyPeer) -> None:
    path = tmp_path / "out.sock"
    with socket.socket(socket.AF_UNIX) as listening:
        listening.bind(str(path))
        done = run_vstig("record", f"serial:{radio.path}", "-o", str(path), "--for", "1", timeout=60)
    assert done.returncode == 2 and f"{path} is a socket" in done.stderr, done.stderr


def test_the_null_device_is_a_sink(radio: PtyPeer) -> None:
    done = run_vstig("record", f"serial:{radio.path}", "-o", os.devnull, "--for", "0.5", timeout=60)
    assert done.returncode == 0, done.stderr


def test_a_terminal_output_is_refused(radio: PtyPeer) -> None:
    other = PtyPeer()  # a terminal nobody reads: a write there would wait on its flow control
    try:
        done = run_vstig("record", f"serial:{radio.path}", "-o", other.path, "--for", "1", timeout=60)
    finally:
        other.close()
    assert done.returncode == 2 and f"{other.path} is a terminal" in done.stderr, done.stderr
