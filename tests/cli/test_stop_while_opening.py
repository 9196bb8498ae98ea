"""A signal that comes while a command's links open, or just after it said "Ctrl-C stops", is a clean stop.

The commands that run until stopped take over SIGTERM before they open their links. Before, bridge, sniff
and record took it over only once their loop ran: a SIGTERM between "bridging ... Ctrl-C stops" and that
moment (seen in a test on a loaded machine) killed the process with no counters, and one during a slow
open did the same. A zenoh link connecting to a peer that is not there waits 3 s in its open: the test
sends SIGTERM as soon as the process has a SIGTERM handler (its SigCgt mask in /proc) and checks that
this came before the command said it runs, and that the command then ends as after any Ctrl-C.
"""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest
from peers import start_vstig, wait_for
from ports import free_port

pytest.importorskip("zenoh", reason="needs the zenoh extra (`make test` installs every extra)")


def _catches(pid: int, signum: int) -> bool:
    """Whether the process has a handler for `signum` (bit signum-1 of SigCgt in /proc/PID/status)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    (mask,) = [line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")]
    return bool(int(mask, 16) >> (signum - 1) & 1)


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
    wait_for(lambda: _catches(process.pid, signal.SIGTERM) or process.poll() is not None, 30)
    assert process.poll() is None, said
    time.sleep(0.2)  # what the command wrote by now, the reader has
    if says is not None:
        assert not any(says in line for line in said), f"it said it runs before it took SIGTERM over: {said}"
    process.terminate()
    assert process.wait(timeout=30) == 0, said
    reader.join(timeout=10)
    assert any(line.startswith("zenoh-lab: ") for line in said), said  # the counters printed at the end
    if says is not None:
        assert any(says in line for line in said), said
