"""A Node's links from open to close, with their reader threads (`readers`) in between."""

from __future__ import annotations

import threading
from typing import Any

from ..links.link import Link
from .delivery import Delivery
from .readers import LinkReaders

__all__ = ["LinkLifecycle"]


class LinkLifecycle:
    """Opens the links, starts a reader per link into the `delivery`, stops them, closes the links."""

    def __init__(self, links: list[Link[Any]], delivery: Delivery) -> None:
        self.links = links
        self._delivery = delivery
        self._readers = LinkReaders(links, delivery.take, delivery.path)
        self._opened: list[Link[Any]] = []

    @property
    def opened(self) -> bool:
        """Whether a link is open (opening, or not closed yet)."""
        return bool(self._opened)

    @property
    def reader_threads(self) -> list[threading.Thread]:
        return list(self._readers.threads)

    def open(self) -> None:
        """Open every link in turn; on failure the ones opened stay open (for `close`) and it raises."""
        for link in self.links:
            link.open()
            self._opened.append(link)

    def start_reading(self) -> None:
        self._readers.start()

    def stop_reading(self) -> None:
        """Stop the readers: a batch that cannot get the Node's lock now is left to the closer (`Delivery`)."""
        self._delivery.stopping = True
        self._readers.stop()

    def close(self) -> None:
        """Close every open link, the last opened first; a device that fails to close is counted (`close_error`)."""
        while self._opened:
            link = self._opened.pop()
            try:
                link.close()
            except Exception:  # closing must reach every link even if one device is already gone
                link.counters["close_error"] += 1
