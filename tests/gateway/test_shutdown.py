"""Ctrl-C/SIGTERM: the first asks for a clean stop, a second one while it is under way ends the process at once.

A repeat within `SAME_STOP_S` of the first is the same stop: `timeout -s INT` signals its command
and then the command's process group, and under load the handler runs for both.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

from vstig_hw.gateway.shutdown import SAME_STOP_S

_SCRIPT = textwrap.dedent("""
    import os, signal, sys, time
    from vstig_hw.gateway.shutdown import stop_on_signals
    gap = float(sys.argv[1])
    with stop_on_signals() as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.01)  # the handler runs between bytecodes
        print("first stop asked" if stop.is_set() else "first ignored", flush=True)
        time.sleep(gap)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(SLEEP)
        print("still running", flush=True)
""").replace("SLEEP", "3")


def _signalled_twice(gap_s: float) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", _SCRIPT, str(gap_s)], capture_output=True, text=True, timeout=30,
                          check=False)


def test_a_second_signal_ends_a_stop_that_hangs() -> None:
    done = _signalled_twice(SAME_STOP_S + 0.1)
    assert done.stdout.splitlines() == ["first stop asked"]
    assert done.returncode == -signal.SIGTERM
    assert "stopping now" in done.stderr


def test_the_same_signal_delivered_twice_at_once_is_one_stop() -> None:
    done = _signalled_twice(0.0)  # the handler has run once already: this is timeout(1)'s second delivery
    assert done.stdout.splitlines() == ["first stop asked", "still running"]
    assert done.returncode == 0
    assert "stopping now" not in done.stderr
