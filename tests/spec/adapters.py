"""The Python framings as the spec tests see them: one thin seam over vstig_hw.framing.

Nothing here re-implements a framing: it only finds the real classes and gives
them the shape the tests use.
"""

from __future__ import annotations

from typing import Any

from vstig_hw.counters import Counters
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.epuck4 import EpuckFragmenter, EpuckReassembler
from vstig_hw.wire import Message


def serial_framing(name: str, **options: Any) -> Any:
    """A fresh serial framing by name (cobs8, epuck4, kilobot, kilobot-ohc)."""
    return make_serial_framing(name, **options)


def epuck_words(msg: Message) -> list[bytes]:
    """The three 4-byte radio words of `msg`."""
    return list(EpuckFragmenter().fragment(msg))


def epuck_reassembler(expiry_ticks: int) -> Any:
    """A fresh reassembler with its own drop counters (`.feed(word)`, `.tick()`, `.drops`)."""
    return EpuckReassembler(Counters(), expiry_ticks=expiry_ticks)


def xbee_receiver(api: int) -> tuple[Any, Any]:
    """(the XBee transport's stream cutting, never opened: `.cut(chunk)`, `.quiet()`, `.counters`; the framing)."""
    from vstig_hw.transports.xbee import XBeeTransport

    return XBeeTransport("unopened", api=api), make_serial_framing("xbee-api2" if api == 2 else "xbee")


def nonzero(counters: Counters) -> dict[str, int]:
    return {name: count for name, count in counters.items() if count}
