"""Framings: each turns one kind of link unit into Messages and back.

Serial framings are built by name (the CLI's and gateway's link specs) through
`make_serial_framing("epuck4", expiry_ticks=5)`.
"""

from __future__ import annotations

import inspect
from typing import Any

from .base import SerialFraming
from .cobs8 import Cobs8Framing
from .epuck4 import Epuck4Framing
from .kilobot import KilobotFraming
from .kilobot_ohc import KilobotOhcFraming, TransmitOnlyError
from .mavlink import MavlinkFraming
from .xbee import XBeeApi2Framing, XBeeFraming

__all__ = ["SERIAL_FRAMINGS", "SerialFraming", "TransmitOnlyError", "make_serial_framing"]



SERIAL_FRAMINGS: dict[str, type[SerialFraming]] = {
    framing.name: framing for framing in (Cobs8Framing, Epuck4Framing, KilobotFraming, KilobotOhcFraming,
                                          XBeeFraming, XBeeApi2Framing, MavlinkFraming)
}


def make_serial_framing(name: str, **options: Any) -> SerialFraming:
    """A fresh framing by its name; unknown names or options raise ValueError naming them."""
    try:
        cls = SERIAL_FRAMINGS[name]
    except KeyError:
        raise ValueError(f"unknown serial framing {name!r}; choose one of {', '.join(SERIAL_FRAMINGS)}") from None
    accepted = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise ValueError(f"serial framing {name!r} has no option {', '.join(map(repr, unknown))}; "
                         f"its options: {', '.join(accepted) or 'none'}")
    return cls(**options)
