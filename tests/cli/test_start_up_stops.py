"""A stop while vstig starts ends it cleanly with its documented status (issue 38, item 2).

vstig takes SIGINT, SIGTERM and SIGHUP over in its first lines, before it imports click,
the library or a command's python-can and zenoh (0.2-0.5 s). Before, a SIGTERM in that
time (and, for the commands that never take signals over, at any time) killed it with
status -15 and no word. Nothing can catch a signal before the interpreter runs vstig's
first line; the tests send theirs the moment vstig catches it, and at fixed moments after.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest
from peers import PtyPeer, catches, start_vstig, wait_for


def _loaded(pid: int, fragment: str) -> bool:
    """Whether a shared object whose path holds `fragment` is mapped in the process (a C extension imported)."""
    try:
        return fragment in Path(f"/proc/{pid}/maps").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.fixture
def radio() -> PtyPeer:
    peer = PtyPeer()
    yield peer  # type: ignore[misc]
    peer.close()


# bridge runs until stopped (a stop is its normal end: 0); get does not (interrupted: 130).
COMMANDS = [(["bridge", "{radio}", "--robot-id", "1"], 0), (["get", "1", "--on", "{radio}", "--wait", "30"], 130)]


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP], ids=["TERM", "INT", "HUP"])
@pytest.mark.parametrize(("command", "status"), COMMANDS, ids=["bridge", "get"])
def test_a_stop_as_soon_as_vstig_runs_is_clean(radio: PtyPeer, command: list[str], status: int,
                                               signum: signal.Signals) -> None:
    process = start_vstig(*(arg.replace("{radio}", f"serial:{radio.path}") for arg in command))
    # vstig takes the three over at once; Python's own SIGINT handler is there from its start, so look for SIGTERM
    wait_for(lambda: catches(process.pid, signal.SIGTERM) or process.poll() is not None, 30,
             step=lambda: time.sleep(0.001))
    early = not _loaded(process.pid, "_cobs")  # before the heavy imports (cobs8 framing: the links' C extension)
    process.send_signal(signum)
    _out, err = process.communicate(timeout=10)
    assert early, "vstig took the signal over only once its links were built"
    assert process.returncode == status, err
    assert "Traceback" not in err and err.strip() == "", err  # nothing had run: nothing to say


@pytest.mark.parametrize("after", [0.3, 0.6, 1.0])
@pytest.mark.parametrize(("command", "status"), COMMANDS, ids=["bridge", "get"])
def test_a_sigterm_at_any_moment_of_start_up_is_clean(radio: PtyPeer, command: list[str], status: int,
                                                      after: float) -> None:
    process = start_vstig(*(arg.replace("{radio}", f"serial:{radio.path}") for arg in command))
    time.sleep(after)
    assert catches(process.pid, signal.SIGTERM), "vstig does not catch SIGTERM after its start"
    process.send_signal(signal.SIGTERM)
    _out, err = process.communicate(timeout=10)
    assert process.returncode == status, err
    assert "Traceback" not in err, err
