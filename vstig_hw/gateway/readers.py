"""Reader threads: one per link, all feeding one queue that the event loop drains.

Only the blocking device read runs on these threads (as python-can's Notifier
does); framing, engine and sending stay on the loop's thread, so none of them
needs a lock. Each batch is stamped with the wall-clock time it was read.

Each link may be at most `READ_AHEAD` batches ahead of the loop: a link that
floods then waits (its device buffers, or its transport drops and counts), so
its batches never pile up in memory nor queue far ahead of another link's.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Any

from ..links.link import Link

__all__ = ["Arrival", "LinkReaders"]

READ_TIMEOUT = 0.05  # how long a read blocks: bounds how long stop() waits for a thread
ERROR_BACKOFF = 0.2
READ_AHEAD = 2  # batches a link may have waiting for the loop

Arrival = tuple[int, float, list[Any]]  # (link index, wall-clock time, units)


class LinkReaders:
    def __init__(self, links: list[Link[Any]]) -> None:
        self.links = links
        self.arrivals: queue.SimpleQueue[Arrival | None] = queue.SimpleQueue()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._slots = [threading.Semaphore(READ_AHEAD) for _ in links]
        self.per_poll = READ_AHEAD * len(links)  # batches the loop handles before it sends again

    def done(self, index: int) -> None:
        """The loop handled a batch of link `index`: its reader may read one more."""
        self._slots[index].release()

    def start(self) -> None:
        self._stop.clear()
        self._slots[:] = [threading.Semaphore(READ_AHEAD) for _ in self.links]
        for index, link in enumerate(self.links):
            thread = threading.Thread(target=self._read, args=(index, link), name=f"read-{link.name}", daemon=True)
            thread.start()
            self._threads.append(thread)

    def _read(self, index: int, link: Link[Any]) -> None:
        read = link.transport.read
        put = self.arrivals.put
        slot = self._slots[index]
        while not self._stop.is_set():
            if not slot.acquire(timeout=READ_TIMEOUT):
                continue
            try:
                units = read(READ_TIMEOUT)
            except Exception:  # transports promise to reconnect quietly; one that raises is counted and retried
                link.counters["read_error"] += 1
                slot.release()
                self._stop.wait(ERROR_BACKOFF)
                continue
            if units:
                put((index, time.time(), units))
            else:
                slot.release()

    def stop(self) -> None:
        self._stop.set()
        self.arrivals.put(None)  # wake the loop if it is waiting
        for thread in self._threads:
            thread.join(timeout=2.0)
        self._threads.clear()
