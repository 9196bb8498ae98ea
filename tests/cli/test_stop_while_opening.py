"""A signal that comes while a command's links open, or just after it said "Ctrl-C stops", is a clean stop.

The commands that run until stopped take over SIGTERM before they open their links (vstig takes it over in
its first lines: test_start_up_stops.py). Before, bridge, sniff and record took it over only once their loop
ran: a SIGTERM between "bridging ... Ctrl-C stops" and that moment (seen in a test on a loaded machine) killed
the process with no counters, and one during a slow open did the same. A zenoh link connecting to a peer that
is not there waits 3 s in its open: the test sends SIGTERM as soon as the process runs a thread besides its
main one (the links open in threads of their own: zenoh's, and the one a stop does not wait for), and checks
that the command then ends as after any Ctrl-C, within 2 s, with its counters.
"""

from __future__ import annotations

import os
import subprocess
import threading
import time
from pathlib import Path

import pytest
from peers import start_vstig, wait_for
from ports import free_port

pytest.importorskip("zenoh", reason="needs the zenoh extra (`make test` installs every extra)")


def _opening(pid: int) -> bool:
    """Whether the process runs more than its main thread (its links open in threads of their own)."""
    try:
        return len(os.listdir(f"/proc/{pid}/task")) > 1
    except FileNotFoundError:
        return False


def _collect(process: subprocess.Popen[str], lines: list[str]) -> None:
    assert process.stderr is not None
    lines.extend(process.stderr)


@pytest.mark.parametrize(("command", "says"), [
    (["bridge", "--robot-id", "200"], "bridging"),
    (["sniff", "--jsonl"], None),
    (["record", "-o", "{tmp}/lab.zcap"], "recording"),
], ids=["bridge", "sniff", "record"])
def test_sigterm_while_the_links_open_is_a_clean_stop(command: list[str], says: str | None, tmp_path: Path) -> None:
    link = f"zenoh:lab?connect=tcp/127.0.0.1:{free_port()}"  # nobody there: the open waits for a peer
    args = [arg.replace("{tmp}", str(tmp_path)) for arg in command]
    process = start_vstig(args[0], link, *args[1:])
    said: list[str] = []
    reader = threading.Thread(target=_collect, args=(process, said), daemon=True)
    reader.start()
    wait_for(lambda: _opening(process.pid) or process.poll() is not None, 30, step=lambda: time.sleep(0.002))
    assert process.poll() is None, said
    started = time.monotonic()
    process.terminate()
    assert process.wait(timeout=30) == 0, said
    took = time.monotonic() - started
    assert took <= 2.0, f"the stop took {took:.1f} s: {said}"  # not the 3 s the peer wait takes
    reader.join(timeout=10)
    assert any(line.startswith("zenoh-lab: ") for line in said), said  # the counters printed at the end
    if says is not None:
        assert any(says in line for line in said), said
