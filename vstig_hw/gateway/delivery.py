"""A Node's delivery: what one read returned, decoded, checked, handled and sent on, on the reader's thread.

C twin: vstig_hw/_cext/path.c (`Path.deliver` is `Delivery.deliver` with `arrive` and the spread in C; index:
vstig_hw/_vstig.pyi).

No hand-offs: each link reads in its own thread (`readers`), and that thread
frames, guards, judges and sends everything one read returned, under the Node's
lock, before it reads again. Which delivery a link's reader calls is chosen once,
when the Node is built (`take`): the compiled one where this install has it (it
hands a batch to the Python one, the reference, while a listener wants each unit
or every `Heard`, or while the readers stop), else the Python one.

A stop delivers or counts: once `stop_taking` handed over every batch already
read, a batch a transport hands over later is counted as `dropped_at_stop`, never
handled half-way. `deliver` is the one place that rule lives.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..links.link import Heard, Link
from ..wire import Message
from .compiled import Compiled, receiver_for
from .delivery_state import DeliveryState
from .guard import Guard
from .listeners import Listeners
from .outbound import Outbound
from .parts import RawRelay, Seat
from .readers import READ_TIMEOUT, Deliver
from .signing import Signing

if TYPE_CHECKING:
    from .._vstig import Receiver

__all__ = ["Delivery"]

log = logging.getLogger(__name__)

Batch = tuple[int, float, list[Any]]  # (link index, wall-clock time read, units)


class Delivery:
    """Decodes, checks and hands on what the links read (see the module's docstring); `take` is what readers call."""

    def __init__(self, links: list[Link[Any]], part: Seat | RawRelay | None, guard: Guard | None,
                 signing: Signing | None, listeners: Listeners, outbound: Outbound, state: DeliveryState,
                 lock: threading.RLock, compiled: Compiled | None) -> None:
        self.links, self.part, self.guard, self.signing = links, part, guard, signing
        self.listeners, self.outbound, self.state, self.lock = listeners, outbound, state, lock
        seat = outbound.seat
        self._admit = seat.admit if seat is not None and seat.intake is not None else None
        # Each link's decoding: its framing's, or its compiled Receiver's (which then decodes for both deliveries).
        receivers: list[Receiver | None] = [None if compiled is None else receiver_for(link) for link in links]
        self.decode: list[Callable[[Any], list[Message]]] = [
            link.decode if receiver is None else receiver.feed for link, receiver in zip(links, receivers, strict=True)]
        if signing is not None:  # each unit's records kept for the check and the engine
            self.decode = [signing.decoder(link, receiver) for link, receiver in zip(links, receivers, strict=True)]
            for link in links:
                link.record_of = signing.record_of(link)
        # what each tick ticks: each link's framing, or its compiled Receiver
        self.tickers: list[Callable[[], None]] = [
            link.tick if receiver is None else receiver.tick for link, receiver in zip(links, receivers, strict=True)]
        self.path = None if compiled is None else compiled.path(
            state, lock, self.deliver, links, receivers, part, guard, outbound.outlets, listeners.path_wants,
            listeners.path_told, listeners.path_delivered)
        # which of a link's peers sent a unit, asked only where the medium says more than the sender (zenoh)
        self._source_of = [link.source_of if link.names_sources else None for link in links]
        self.take: Deliver = self.deliver if self.path is None else self._deliver_compiled
        self.stopping = False  # the readers are stopping: a batch that cannot get the lock is left for the closer
        self._taking = True  # batches are handled; False once a stop handed over what was read (later: counted)
        self._leftover: list[Batch] = []  # batches read while closing, for `stop_taking`

    def deliver(self, index: int, t: float, units: list[Any]) -> None:
        """On link `index`'s reader thread: handle what one read returned, and send what it caused, at once.

        Everything the read returned is heard before anything is sent (one batch per
        write). The loop is woken only when it must look: a budget window holds
        messages back sooner than it would look by itself, or it waits for a drain.
        """
        lock = self.lock
        appended = False
        while not (lock.acquire(False) or lock.acquire(True, READ_TIMEOUT)):  # the first try parses no keywords
            if self.stopping and not appended:  # the closer may hold the lock: it hands this batch on
                self._leftover.append((index, t, units))
                appended = True
                if self._taking:  # else the closer may be past its leftovers: count what it left, below
                    return
        if not self._taking:  # after the stop handed over what was read: counted, not handled half-way
            try:
                self._count_unhandled(None if appended else (index, units))
            finally:
                lock.release()
            return
        state = self.state
        state.reader_thread = threading.get_ident()
        try:
            self.arrive(index, t, units)
            self.outbound.spread(time.monotonic(), 1 << index)
            for delivered in self.listeners.delivered:
                delivered(t)
        except BaseException as failure:  # a listener broke: the loop raises it on its thread, and the Node closes
            if state.failure is None:
                state.failure = failure
            state.wake.set()
            return
        finally:
            state.reader_thread = 0
            lock.release()
        retry = state.retry_at  # read after spread set it; the loop sets sleep_until before reading it
        if state.wake_on_arrival or (retry is not None and retry < state.sleep_until):
            state.wake.set()

    def _deliver_compiled(self, index: int, t: float, units: list[Any]) -> None:
        """`deliver` for what a transport's own read returned, by the compiled delivery where it can."""
        path = self.path
        assert path is not None
        if not path.deliver(index, t, units):
            self.deliver(index, t, units)

    def stop_taking(self, label: str) -> None:
        """Under the lock, once the readers stopped: hand every batch read meanwhile over; any later is counted."""
        self._taking = False  # before the leftovers are taken: one appended later is `deliver`'s to count
        leftover, self._leftover = self._leftover, []
        for batch in leftover:
            try:
                self.arrive(*batch)
            except Exception:  # a listener that breaks now must not keep the links open
                log.exception("a listener of %s failed while it stopped", label)

    def _count_unhandled(self, batch: tuple[int, list[Any]] | None) -> None:
        """Count as `dropped_at_stop` the messages of `batch` and of any leftovers nobody will hand over now:
        units a transport returned after the stop handed over what was read (under the lock)."""
        late = [(index, units) for index, _t, units in self._leftover]
        self._leftover = []
        if batch is not None:
            late.append(batch)
        for index, units in late:
            decode = self.decode[index]
            self.links[index].counters["dropped_at_stop"] += sum(len(decode(unit)) for unit in units)

    def arrive(self, index: int, t: float, units: list[Any]) -> None:
        """Decode, check and hand to the part what one read of link `index` returned (under the lock)."""
        link = self.links[index]
        decode = self.decode[index]
        sender_of = link.sender_of
        part = self.part
        guard = self.guard
        listeners = self.listeners
        on_unit, on_heard, on_messages = listeners.unit, listeners.heard, listeners.messages
        source_of = self._source_of[index]
        admit = self._admit
        signing = self.signing
        heard_count = 0
        for unit in units:
            for listener in on_unit:
                listener(link, t, unit)
            messages = decode(unit)
            if not messages:
                continue
            heard_count += len(messages)
            if signing is not None:  # tags by the link's policy, before the guard and the intake
                messages = signing.check(link, messages, t, sender_of(unit), listeners.refused)
                if not messages:
                    continue
            source = source_of(unit) if source_of is not None else None  # which of the link's peers sent it
            if admit is not None:  # the engine's intake per source, before any other work
                messages = admit(index, source, messages, t)
                if not messages:
                    continue
            sender = sender_of(unit) if guard is not None or on_heard or listeners.change or on_messages else None
            told = False
            if guard is not None:
                if listeners.refused:
                    messages, told = self._judge_and_tell(guard, link, sender, source, messages, t), True
                else:
                    messages = guard.filter(link.name, sender, messages, t, link.counters, source)
            if on_heard and not told:
                for msg in messages:
                    heard = Heard(msg, link.name, t, sender)
                    for h_listener in on_heard:
                        h_listener(heard)
            if messages:
                for m_listener in on_messages:
                    m_listener(link.name, t, sender, messages)
            if part is not None and messages:
                part.take(index, messages, sender, source)
        link.counters["in"] += heard_count

    def _judge_and_tell(self, guard: Guard, link: Link[Any], sender: int | None, source: str | None,
                        messages: list[Message], t: float) -> list[Message]:
        """Tell the listeners every message, passed (heard) or refused (refused), in the order heard,
        as a sniffer shows them; the ones that passed."""
        kept = []
        listeners = self.listeners
        for msg in messages:
            reason = guard.check(link.name, sender, msg, t, source)
            heard = Heard(msg, link.name, t, sender)
            if reason is None:
                kept.append(msg)
                for h_listener in listeners.heard:
                    h_listener(heard)
            else:
                link.counters[reason] += 1
                for r_listener in listeners.refused:
                    r_listener(heard, reason)
        return kept

