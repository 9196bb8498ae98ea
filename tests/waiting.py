"""Waiting in a test for what a Node's own threads do (the Node runs its loop itself: tests only watch)."""

from __future__ import annotations

import time
from collections.abc import Callable

POLL = 0.005  # seconds between two looks


def wait_until(done: Callable[[], bool], timeout: float = 10.0, step: Callable[[], None] | None = None) -> None:
    """Look at `done()` (after `step()`, if given) until it is true; fail naming `timeout` when it never is."""
    end = time.monotonic() + timeout
    while True:
        if step is not None:
            step()
        if done():
            return
        assert time.monotonic() < end, f"not done within {timeout:g} s"
        time.sleep(POLL)
