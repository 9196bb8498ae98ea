"""A wait that a signal handler interrupts still ends when its time is up (Python 3.11's SimpleQueue does not)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time

from vstig_hw.wakeup import Wakeup

# A signal arrives during the wait and its handler runs past the wait's end: the case that hung `vstig record`.
_SLOW_HANDLER = """
import signal, time
def handler(signum, frame):
    time.sleep(0.3)
signal.signal(signal.SIGALRM, handler)
def alarm_soon():  # 0.1 s into a 0.2 s wait
    signal.setitimer(signal.ITIMER_REAL, 0.1)
"""


def _ends_in_time(body: str) -> None:
    script = _SLOW_HANDLER + textwrap.dedent(body) + "\nprint('ended')\n"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=20, check=False)
    assert done.returncode == 0 and done.stdout.strip() == "ended", done.stderr


def test_a_wait_interrupted_by_a_slow_signal_handler_ends() -> None:
    _ends_in_time("""
        from vstig_hw.wakeup import Wakeup
        wake = Wakeup()
        alarm_soon()
        assert wake.wait(0.2) is False
    """)


def test_a_wait_on_a_running_node_interrupted_by_a_slow_signal_handler_ends() -> None:
    _ends_in_time("""
        from vstig_hw.gateway import Node, Mode
        from vstig_hw.links import parse
        node = Node([parse("can:virtual:wakeup-test").build("bus")], mode=Mode.LISTEN)
        with node:
            alarm_soon()
            assert node.wait_closed(0.2) is False
    """)


def test_wake_ups_given_before_a_wait_are_one() -> None:
    wake = Wakeup()
    wake.set()
    wake.set()
    assert wake.wait(0) is True
    assert wake.wait(0) is False
    start = time.monotonic()
    assert wake.wait(0.05) is False
    assert time.monotonic() - start >= 0.04


def test_a_wake_up_from_another_thread_ends_the_wait_at_once() -> None:
    wake = Wakeup()
    threading.Timer(0.05, wake.set).start()
    start = time.monotonic()
    assert wake.wait(5.0) is True
    assert time.monotonic() - start < 2.0
