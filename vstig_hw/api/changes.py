"""Changes to a swarm's table, handed from the gateway's thread to whoever watches, never holding it up.

The gateway thread `offer`s each change to every subscription: an append to a
bounded buffer, and a wake-up only when the reader is waiting. A reader that
falls behind loses the oldest changes, counted in `overflow` (the newest says
what the table holds now), and the gateway never waits for it.

`Watch` is read from a thread (an iterator), `AsyncWatch` from an asyncio loop
(an async iterator); both carry a table's `Change`s (`Watch[Change]`) or the
roster's state changes (`Watch[StateChange]`: `Swarm.watch_robots`). And an
`on_change` callback runs on a thread of its own reading a Watch, so a callback that calls back into the swarm (even a
confirmed put) waits for the gateway thread, which is free, instead of
deadlocking it.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Generic, NamedTuple, TypeVar

from ..engine import Entry

__all__ = ["DEFAULT_BUFFER", "AsyncWatch", "Change", "ChangeHub", "Hub", "OnChange", "Subscription", "Watch"]

DEFAULT_BUFFER = 4096  # changes a subscription holds before the oldest are dropped (counted)

log = logging.getLogger("vstig_hw.api")


class Change(NamedTuple):
    """One change of the table: `key` went from `old` (None: a new key) to `new`.

    `link` is the name of the link it was heard on (None: this program's own put);
    `sender` is the robot that sent it where the medium names senders (CAN IDs),
    else None. Values in the entries are the raw 16-bit wire values.
    """

    key: int
    old: Entry | None
    new: Entry
    link: str | None
    sender: int | None


# What a subscription carries: a Change, or a roster's StateChange; `keys` chooses by its first field (a key, a robot).
Item = TypeVar("Item", bound=tuple[Any, ...])


class Subscription(Generic[Item]):
    """A bounded buffer of changes, filled by the gateway thread; `overflow` counts the changes dropped."""

    def __init__(self, keys: Iterable[int] | None, buffer: int) -> None:
        if isinstance(buffer, bool) or not isinstance(buffer, int) or buffer < 1:
            raise ValueError(f"buffer must be a positive number of changes, got {buffer!r}")
        self.keys = None if keys is None else frozenset(keys)
        self.buffer = buffer
        self.overflow = 0
        self.delivered = 0
        self.closed = False
        self._changes: collections.deque[Item] = collections.deque()
        self._waiting = False
        self._hub: Hub[Item] | None = None

    def offer(self, change: Item) -> None:
        """Called on the gateway thread: never blocks."""
        if self.keys is not None and change[0] not in self.keys:
            return
        changes = self._changes
        if len(changes) >= self.buffer:
            try:
                changes.popleft()
                self.overflow += 1
            except IndexError:  # the reader emptied it meanwhile: nothing lost
                pass
        changes.append(change)
        if self._waiting:  # one wake-up per wait, however many changes come before the reader runs
            self._waiting = False
            self._wake()

    def close(self) -> None:
        """Stop receiving; a reader gets what is buffered, then the end."""
        if self._hub is not None:
            self._hub.remove(self)
        self.closed = True
        self._wake()

    def _pop(self) -> Item | None:
        try:
            change = self._changes.popleft()
        except IndexError:
            return None
        self.delivered += 1
        return change

    def _wake(self) -> None:
        raise NotImplementedError


class Watch(Subscription[Item]):
    """Changes as a blocking iterator, for a thread; it ends when the swarm closes (or `close`)."""

    def __init__(self, keys: Iterable[int] | None = None, buffer: int = DEFAULT_BUFFER) -> None:
        super().__init__(keys, buffer)
        self._event = threading.Event()

    def get(self, timeout: float | None = None) -> Item | None:
        """The next change, waiting up to `timeout` seconds (None: for ever); None on timeout or once closed."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            change = self._pop()
            if change is not None or self.closed:
                return change
            self._event.clear()
            self._waiting = True
            change = self._pop()  # offered before _waiting was set: no wake-up comes for it
            if change is not None:
                self._waiting = False
                return change
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                self._waiting = False
                return None
            self._event.wait(left)
            self._waiting = False

    def __iter__(self) -> Iterator[Item]:
        return self

    def __next__(self) -> Item:
        change = self.get()
        if change is None:
            raise StopIteration
        return change

    def __enter__(self) -> Watch[Item]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _wake(self) -> None:
        self._event.set()


class AsyncWatch(Subscription[Item]):
    """Changes as an async iterator on the asyncio loop that made it; it ends when the swarm closes."""

    def __init__(self, keys: Iterable[int] | None = None, buffer: int = DEFAULT_BUFFER) -> None:
        super().__init__(keys, buffer)
        self._loop = asyncio.get_running_loop()
        self._future: asyncio.Future[None] | None = None

    async def get(self) -> Item | None:
        """The next change; None once closed and drained."""
        while True:
            change = self._pop()
            if change is not None or self.closed:
                return change
            self._future = self._loop.create_future()
            self._waiting = True
            change = self._pop()
            if change is not None:
                self._waiting = False
                return change
            try:
                await self._future
            finally:
                self._waiting = False

    def __aiter__(self) -> AsyncWatch[Item]:
        return self

    async def __anext__(self) -> Item:
        change = await self.get()
        if change is None:
            raise StopAsyncIteration
        return change

    def _wake(self) -> None:
        future = self._future
        if future is None:
            return
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody is waiting any more
            self._loop.call_soon_threadsafe(_settle, future)


def _settle(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class OnChange:
    """An `on_change` callback running on a thread of its own, fed by a Watch; `cancel` stops it."""

    def __init__(self, callback: Callable[[Change], object], watch: Watch[Change], errors: Callable[[], None]) -> None:
        self.callback = callback
        self.watch = watch
        self._errors = errors
        name = getattr(callback, "__name__", "callback")
        self._thread = threading.Thread(target=self._run, name=f"vstig-on-change-{name}", daemon=True)
        self._thread.start()

    @property
    def overflow(self) -> int:
        """Changes dropped because the callback fell behind."""
        return self.watch.overflow

    def cancel(self, wait: float = 2.0) -> None:
        """Stop calling back (what is buffered is still handed over first); waits for the thread unless on it."""
        self.watch.close()
        if threading.current_thread() is not self._thread:
            self._thread.join(wait)

    def _run(self) -> None:
        for change in self.watch:
            try:
                self.callback(change)
            except Exception:  # one bad change must not end the callbacks: logged and counted
                log.exception("on_change callback %r failed on %r", self.callback, change)
                self._errors()


class Hub(Generic[Item]):
    """The subscriptions of one swarm to one kind of change; `offer` hands one to each (gateway thread)."""

    def __init__(self, attach: Callable[[bool], None]) -> None:
        self._attach = attach  # called with True when the first subscription comes, False when the last goes
        self._subscriptions: tuple[Subscription[Item], ...] = ()  # replaced, never mutated: read unlocked
        self._lock = threading.Lock()
        self.closed = False

    def add(self, subscription: Subscription[Item]) -> None:
        """Start handing changes to `subscription` (closed at once if the hub is)."""
        with self._lock:
            if self.closed:
                subscription.closed = True
                return
            subscription._hub = self
            self._subscriptions = (*self._subscriptions, subscription)
            if len(self._subscriptions) == 1:
                self._attach(True)

    def remove(self, subscription: Subscription[Item]) -> None:
        """Stop handing changes to `subscription`."""
        with self._lock:
            if subscription not in self._subscriptions:
                return
            self._subscriptions = tuple(s for s in self._subscriptions if s is not subscription)
            if not self._subscriptions and not self.closed:
                self._attach(False)

    def offer(self, change: Item) -> None:
        """Offer one change to every subscription (the gateway thread; never blocks)."""
        for subscription in self._subscriptions:
            subscription.offer(change)

    def close(self) -> None:
        """End every subscription (their readers drain what is buffered)."""
        with self._lock:
            self.closed = True
            subscriptions, self._subscriptions = self._subscriptions, ()
        for subscription in subscriptions:
            subscription.closed = True
            subscription._wake()

    def overflow(self) -> int:
        """Changes dropped, summed over the subscriptions."""
        return sum(s.overflow for s in self._subscriptions)


class ChangeHub(Hub[Change]):
    """A swarm's table's subscriptions; `publish` is the Node's `change` listener (gateway thread)."""

    def publish(self, key: int, old: Entry | None, new: Entry, link: str | None, sender: int | None) -> None:
        change = Change(key, old, new, link, sender)
        for subscription in self._subscriptions:  # (`offer`'s loop, a call less per change)
            subscription.offer(change)
