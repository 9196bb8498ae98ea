"""The transport contract: a device that moves raw units, and nothing more.

A transport owns one device (a pyserial port, a python-can bus). It never
interprets payloads. It survives the device vanishing: `read` and `write`
reconnect with backoff and report the loss once (see `state`), instead of
raising into the caller's loop.
"""

from __future__ import annotations

from typing import Generic, Protocol, TypeVar

from ..counters import Counters

Unit = TypeVar("Unit")


def errno_of(exc: BaseException) -> int | None:
    """The OS error number behind a pyserial/python-can exception: in `.errno`, `.error_code` or a cause."""
    seen: BaseException | None = exc
    while seen is not None:
        for attr in ("errno", "error_code"):
            code = getattr(seen, attr, None)
            if isinstance(code, int):
                return code
        seen = seen.__cause__ or seen.__context__
    return None


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (its type name when it has none)."""
    return " ".join(str(exc).split()) or type(exc).__name__


class TransportError(Exception):
    """A device problem the user must fix; the message is one clear line naming the device."""


class Transport(Protocol, Generic[Unit]):
    name: str  # how the user named the device, for messages and counters
    counters: Counters  # rx/tx units, reconnects, bus errors...

    def open(self) -> None:
        """Open the device; raise TransportError with a one-line reason if it cannot be."""
        ...

    def close(self) -> None: ...

    def read(self, timeout: float) -> list[Unit]:
        """Units received within `timeout` seconds (maybe none). Reconnects quietly when the device is gone."""
        ...

    def write(self, unit: Unit) -> None:
        """Send one unit; while the device is gone the unit is dropped and counted, not raised."""
        ...

    @property
    def connected(self) -> bool: ...
