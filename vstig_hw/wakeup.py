"""A wake-up one thread waits for and any thread gives, safe against signals.

CPython 3.11's `queue.SimpleQueue.get(timeout=...)` can block forever when a
signal handler runs during the wait and the time left has passed by the time it
returns (the timeout is recomputed as negative, which means "wait forever"). A
`vstig record` waiting there ignored its SIGTERM that way. `threading.Lock`'s
timed acquire recomputes the time left correctly, so the token here is a lock.
"""

from __future__ import annotations

import threading

__all__ = ["Wakeup"]


class Wakeup:
    """One token: `set` gives it (several before a `wait` are one), `wait` takes it or times out."""

    def __init__(self) -> None:
        self._token = threading.Lock()
        self._token.acquire()  # held: no token yet

    def set(self) -> None:
        """Give the token; safe from any thread, never blocks."""
        try:  # noqa: SIM105 (contextlib.suppress would add a Python-level context manager to every wake-up)
            self._token.release()
        except RuntimeError:  # the token is there already
            pass

    def wait(self, timeout: float) -> bool:
        """Take the token, waiting up to `timeout` seconds (0: only look); whether there was one."""
        if timeout > 0:
            return self._token.acquire(True, timeout)
        return self._token.acquire(False)
