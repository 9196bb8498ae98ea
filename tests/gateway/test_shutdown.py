"""Ctrl-C/SIGTERM: the first asks for a clean stop, a second one while it is under way ends the process at once."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

_SCRIPT = textwrap.dedent("""
    import os, signal, time
    from vstig_hw.gateway.shutdown import stop_on_signals
    with stop_on_signals() as stop:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.1)  # the handler runs between bytecodes
        print("first stop asked" if stop.is_set() else "first ignored", flush=True)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
        print("still running", flush=True)
""")


def test_a_second_signal_ends_a_stop_that_hangs() -> None:
    done = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True, timeout=30, check=False)
    assert done.stdout.splitlines() == ["first stop asked"]
    assert done.returncode == -signal.SIGTERM
    assert "stopping now" in done.stderr
