"""A Node's life from open to close: its links, a reader thread per link, its loop's thread, and the stop.

One way to own a Node: `open` opens the links, starts their readers and starts the loop on a thread of the
Node's own; `close` stops it, from any thread, once. Nobody else drives the loop.

A stop delivers or counts: the ticks pause (no refresh, no asks), the readers stop and every batch they
already read is handed to the part and the listeners; a transport that hands over anything later (a read that
outlived the stop, a device's callback in flight) has its messages counted as `dropped_at_stop`, never handled
half-way (`Delivery`). Then what the budget held back goes out (at most `drain` seconds, at the budget's pace),
the devices get the rest of that time to take what the writers hold, what is left is counted
(`unsent_at_close`), the links close, and the `closed` listeners are told.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from ..links.link import Link
from .delivery import Delivery
from .listeners import Listeners
from .loop import Loop
from .outbound import Outbound
from .readers import LinkReaders

__all__ = ["CLOSE_DRAIN", "LinkLifecycle", "SwarmClosed"]

CLOSE_DRAIN = 1.0  # seconds `close` gives what is held back and what the devices hold, by default

log = logging.getLogger(__name__)


class SwarmClosed(RuntimeError):
    """The swarm was closed (or its gateway stopped): no call reaches it any more."""


class LinkLifecycle:
    """Opens a Node's links and starts its threads; stops them and closes the links (see the module's docstring)."""

    def __init__(self, label: str, links: list[Link[Any]], delivery: Delivery, outbound: Outbound, loop: Loop,
                 listeners: Listeners, lock: threading.RLock, drain_until: Callable[[float, bool], bool]) -> None:
        self.label, self.links = label, links
        self._delivery, self._outbound, self._loop, self._listeners, self._lock = delivery, outbound, loop, \
            listeners, lock
        self._drain_until = drain_until
        self._readers = LinkReaders(links, delivery.take, delivery.path)
        self._opened: list[Link[Any]] = []
        self.failure: BaseException | None = None  # what broke the loop, which closed the Node (None: nothing)
        self.closed_because: str | None = None  # why no call gets in any more (None: open for calls)
        self.shut = False  # the links were closed (or are being closed)
        self._shutting = threading.Lock()
        self._finished = threading.Event()  # the stop is over: every link closed
        self._close_drain = CLOSE_DRAIN

    @property
    def reader_threads(self) -> list[threading.Thread]:
        return list(self._readers.threads)

    def open(self, thread_name: str) -> None:
        """Open every link, start their readers and the loop's thread; on failure close what opened, re-raise."""
        if self._loop.started or self.shut:
            raise RuntimeError(f"{self.label} was opened once already")
        try:
            for link in self.links:
                link.open()
                self._opened.append(link)
        except BaseException:
            self.close(drain=0.0, on_node_thread=False)
            raise
        self._readers.start()
        self._loop.start(thread_name, self._ended)

    def close(self, drain: float, on_node_thread: bool) -> None:
        """From the Node's own threads ask the loop to stop and return (its thread then closes); from another
        thread wait until the Node closed. A Node whose loop never ran closes here."""
        self._close_drain = drain
        loop = self._loop
        if loop.running:
            loop.request_stop()
            if not on_node_thread:
                loop.join()
            return
        self._shutdown(0.0 if on_node_thread else drain)

    def wait_closed(self, timeout: float | None) -> bool:
        return self._finished.wait(timeout)

    def closed_error(self) -> SwarmClosed:
        return SwarmClosed(f"{self.label} is closed: {self.closed_because}")

    def _ended(self, failure: BaseException | None) -> None:
        """On the loop's thread once it returned: a failure closes the Node naming it (`failure`, for whoever
        reports it: the command raises it, the Python API logs it); then the stop."""
        if failure is not None:
            with self._lock:
                self.failure = failure
                if self.closed_because is None:
                    self.closed_because = f"its gateway stopped: {type(failure).__name__}: {failure}"
        self._shutdown(self._close_drain)

    def _shutdown(self, drain: float) -> None:
        """The stop, once (see the module's docstring)."""
        with self._shutting:
            if self.shut:
                return
            self.shut = True
        deadline = time.monotonic() + drain
        with self._lock:
            if self.closed_because is None:
                self.closed_because = "it was closed"
            self._loop.paused = True
        self._delivery.stopping = True  # a batch that cannot get the lock now is left to `stop_taking`
        self._readers.stop()
        with self._lock:  # what the readers read is handed over; whatever comes later is counted
            self._delivery.stop_taking(self.label)
        self._loop.fail_calls(self.closed_error)
        if self._opened and self._outbound.outlets and self._loop.on_thread():
            self._drain_until(deadline, False)
        self._outbound.close(deadline)
        while self._opened:
            link = self._opened.pop()
            try:
                link.close()
            except Exception:  # closing must reach every link even if one device is already gone
                link.counters["close_error"] += 1
        self._finished.set()
        for listener in self._listeners.closed:
            try:
                listener()
            except Exception:
                log.exception("a closed listener of %s failed", self.label)
