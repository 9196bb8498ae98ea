"""The framing contract: link units <-> Messages, pure and counted.

A framing is a small pure class: no device, no thread, no clock. `encode` turns
one Message into the units the transport writes (bytes for a UART, frames for
CAN); `feed` takes whatever unit the transport read and returns the Messages now
complete. Anything that cannot be a message is dropped and counted in `drops`
by reason, never raised.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Generic, Protocol, TypeVar

from ..counters import Counters
from ..wire import Message

Unit = TypeVar("Unit")


class Framing(Protocol, Generic[Unit]):
    name: str
    drops: Counters

    def encode(self, msg: Message) -> Sequence[Unit]:
        """The units that carry `msg`, in transmission order."""
        ...

    def feed(self, unit: Unit) -> list[Message]:
        """Messages completed by this unit (possibly none); bad input is counted in `drops`."""
        ...

    def tick(self) -> None:
        """One control period passed (expires stale partial state; no-op for most framings)."""
        ...
