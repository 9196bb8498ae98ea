"""Reader threads: one per link, each handing what its device returned straight to a `deliver` callback.

Only the blocking device read waits here, one thread per link (as python-can's
Notifier does). What a read returned is handed over in the same thread, with
no queue and no wake-up of another thread: the Node then frames, guards, judges
and sends the whole batch under its lock before this thread reads again (see
`Delivery.deliver`). Each batch is stamped with the wall-clock time it was read.

A link that floods therefore waits for its own batch to be handled before it
reads more (its device buffers, or its transport drops and counts), and the
Node's lock, taken per batch, lets every other link in between.

A transport whose device calls us back (Zenoh's subscriber) hands what it heard
over from that callback (`deliver_to`), so nothing waits in a queue for the read
thread; its read thread still runs, for the transport's reconnects and watches.
"""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..links.link import Link

if TYPE_CHECKING:
    from .._vstig import Path

__all__ = ["Arrival", "LinkReaders"]

READ_TIMEOUT = 0.05  # how long a read blocks: bounds how long stop() waits for a thread
ERROR_BACKOFF = 0.2

Arrival = tuple[int, float, list[Any]]  # (link index, wall-clock time, units)
Deliver = Callable[[int, float, list[Any]], None]


class LinkReaders:
    """One reader thread per link. With a compiled delivery (`path`), a link whose device it reads itself (a
    serial port's fd, a SocketCAN socket: `path.pumps`) is read and delivered by it, one call per read; the
    transport's own read takes a turn whenever the path hands it back (no fd now, a device failing, a listener
    that wants python-can's own messages)."""

    def __init__(self, links: list[Link[Any]], deliver: Deliver, path: Path | None = None) -> None:
        self.links = links
        self.deliver = deliver
        self.path = path
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    @property
    def threads(self) -> list[threading.Thread]:
        """The reader threads running now (one per link)."""
        return self._threads

    def start(self) -> None:
        self._stop.clear()
        if self.path is not None:
            self.path.stopping = False
        for index, link in enumerate(self.links):
            link.deliver_to(functools.partial(self._pushed, index))  # a device that calls back hands over at once
            pumped = self.path is not None and self.path.pumps(index)
            thread = threading.Thread(target=self._pump if pumped else self._read, args=(index, link),
                                      name=f"read-{link.name}", daemon=True)
            thread.start()
            self._threads.append(thread)

    def _read(self, index: int, link: Link[Any]) -> None:
        read = link.read
        deliver = self.deliver
        while not self._stop.is_set():
            try:
                units = read(READ_TIMEOUT)
            except Exception:  # transports promise to reconnect quietly; one that raises is counted and retried
                link.counters["read_error"] += 1
                self._stop.wait(ERROR_BACKOFF)
                continue
            if units:
                deliver(index, time.time(), units)

    def _pump(self, index: int, link: Link[Any]) -> None:
        """The compiled delivery reads the device in its own loop (`serve`) until `stop`; the transport's own
        read takes the turns it hands back (`_read_once`)."""
        path = self.path
        assert path is not None
        turn = functools.partial(self._read_once, index, link)
        while not self._stop.is_set():
            try:
                path.serve(index, READ_TIMEOUT, turn)
            except Exception:  # as `_read`: counted and retried
                link.counters["read_error"] += 1
                self._stop.wait(ERROR_BACKOFF)

    def _read_once(self, index: int, link: Link[Any]) -> None:
        units = link.read(READ_TIMEOUT)
        if units:
            self.deliver(index, time.time(), units)

    def _pushed(self, index: int, units: list[Any]) -> None:
        """On the device's own thread (a transport's callback): what it heard, delivered as a read's would be."""
        self.deliver(index, time.time(), units)

    def stop(self) -> None:
        self._stop.set()
        if self.path is not None:
            self.path.stopping = True
        for link in self.links:
            link.deliver_to(None)
        me = threading.current_thread()
        for thread in self._threads:
            if thread is not me:  # a listener on a reader thread may close the node
                thread.join(timeout=2.0)
        self._threads.clear()
