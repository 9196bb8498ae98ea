"""Who a Node tells what it does (`Node.listen`): the listeners by kind, kept where both deliveries read them.

What each kind is told:

* `unit(link, t, unit)`: every unit a link read, before it is decoded (a recorder);
* `heard(Heard)`: every message that passed the guard, in the order heard;
* `refused(Heard, reason)`: every message the guard refused, with its drop counter's name;
* `messages(link_name, t, sender, messages)`: what one unit carried past the guard, one call
  per unit and no `Heard` built (cheaper than `heard` on a busy gateway);
* `change(key, old, new, link_name, sender)`: our table's entry changed (`link_name` None:
  our own put); the engine tells changes only while someone listens;
* `tick(node)`: every control period, on the loop's thread (not while a stop drains);
* `delivered(t)`: a batch read at wall-clock time `t` was handled and what it caused handed to
  the links (written, or queued to a slow link's writer): the relay latency;
* `closed()`: once, after the Node closed (every frame read handed over, the links closed).

All but `closed` run under the Node's lock on the thread that did the work (a reader's, the loop's, a caller's).

The listeners are held one tuple per kind, replaced (never changed) by `add` and
`remove`: a delivery reads them without a copy, and a listener may cancel itself
while they are gone through. The compiled delivery (`Path`) reads the same
listeners through three lists it was handed once (`for_path`), which every change
here updates in place; a Seat tells `change` itself, so its `on_change` is kept
equal too.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from typing import Any

from ..links.link import Heard, Link
from ..wire import Message
from .parts import ChangeListener, Seat

__all__ = ["ChangeListener", "ClosedListener", "DeliveredListener", "HeardListener", "Listeners", "Listening",
           "MessagesListener", "RefusedListener", "TickListener", "UnitListener"]

UnitListener = Callable[[Link[Any], float, Any], None]
HeardListener = Callable[[Heard], None]
RefusedListener = Callable[[Heard, str], None]  # a message the guard refused, and its drop counter name
# Called with the Node; typed Any here since this module sits below node.py (Node.listen names the type).
TickListener = Callable[[Any], None]
# What one unit carried, after the guard: link name, time heard, sender (None: the medium names none), messages.
# Cheaper than `heard` on a busy gateway: one call per unit and no `Heard` built (the live view uses it).
MessagesListener = Callable[[str, float, "int | None", list[Message]], None]
# A batch was handled and what it caused handed to the links (written, or queued to a slow link's writer):
# called with the wall-clock time the batch was read (the metrics' relay latency).
DeliveredListener = Callable[[float], None]
ClosedListener = Callable[[], None]


class Listening:
    """Calls a Node makes to one listener (`Node.listen`); `cancel()` stops them: safe twice, from any thread,
    even from inside one of them (the batch being handled then may still reach the others)."""

    def __init__(self, listeners: Listeners, unit: UnitListener | None, heard: HeardListener | None,
                 refused: RefusedListener | None, messages: MessagesListener | None, change: ChangeListener | None,
                 tick: TickListener | None, delivered: DeliveredListener | None, closed: ClosedListener | None) -> None:
        self._listeners = listeners
        self.unit, self.heard, self.refused, self.messages = unit, heard, refused, messages
        self.change, self.tick, self.delivered, self.closed = change, tick, delivered, closed
        self.active = True

    def cancel(self) -> None:
        """Stop the calls; once it returns (from another thread than the Node's) none is running any more."""
        self._listeners.remove(self)

    def __enter__(self) -> Listening:
        return self

    def __exit__(self, *exc: object) -> None:
        self.cancel()


class Listeners:
    """A Node's listeners, one tuple per kind (see the module's docstring); changed under the Node's `lock`."""

    def __init__(self, lock: threading.RLock) -> None:
        self._lock = lock
        self._every: list[Listening] = []
        self.seat: Seat | None = None  # told `change` itself (set once the Node built it)
        self.unit: tuple[UnitListener, ...] = ()
        self.heard: tuple[HeardListener, ...] = ()
        self.refused: tuple[RefusedListener, ...] = ()  # what the guard refused (a sniffer shows it too)
        self.messages: tuple[MessagesListener, ...] = ()
        self.change: tuple[ChangeListener, ...] = ()  # the table changed (Python API's watch); see `Seat`
        self.tick: tuple[TickListener, ...] = ()
        self.delivered: tuple[DeliveredListener, ...] = ()  # a batch handled and handed on (metrics' latency)
        self.closed: tuple[ClosedListener, ...] = ()
        # The compiled delivery's view: those that want each unit or every `Heard` (it then hands the batch to
        # the Python delivery), the `messages` and `refused` it tells itself, the `delivered`.
        self.path_wants: list[Sequence[Any]] = []
        self.path_told: list[tuple[Callable[..., None], ...]] = [(), ()]
        self.path_delivered: list[DeliveredListener] = []

    def add(self, listening: Listening) -> None:
        with self._lock:
            self._every.append(listening)
            self._rebuild()

    def remove(self, listening: Listening) -> None:
        with self._lock:
            if listening.active:
                listening.active = False
                self._every.remove(listening)
                self._rebuild()

    def _rebuild(self) -> None:
        every = self._every
        self.unit = tuple(x.unit for x in every if x.unit is not None)
        self.heard = tuple(x.heard for x in every if x.heard is not None)
        self.refused = tuple(x.refused for x in every if x.refused is not None)
        self.messages = tuple(x.messages for x in every if x.messages is not None)
        self.change = tuple(x.change for x in every if x.change is not None)
        self.tick = tuple(x.tick for x in every if x.tick is not None)
        self.delivered = tuple(x.delivered for x in every if x.delivered is not None)
        self.closed = tuple(x.closed for x in every if x.closed is not None)
        if self.seat is not None:
            self.seat.on_change = self.change
        self.path_wants[:] = [self.unit, self.heard]
        self.path_told[:] = [self.messages, self.refused]
        self.path_delivered[:] = self.delivered
