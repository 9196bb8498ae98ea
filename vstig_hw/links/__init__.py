"""Links: one transport plus one framing, the unit the gateway wires together.

This package is the one place links are assembled:

- `link`: `Link` and `Heard`, the medium-independent unit;
- `spec`: the link-spec grammar (`parse("can:socketcan:vcan0")`);
- one builder module per medium (`serial`, `can`, `zenoh`).

Framings stay pure: none of them imports a transport or a link. The builders
are loaded on first use, so a command imports only the media it opens
(python-can alone costs tens of milliseconds).
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from .link import Heard, Link
from .spec import EXAMPLES, GRAMMAR, CanSpec, LinkSpec, SerialSpec, ZenohSpec, parse

__all__ = [
    "EXAMPLES",
    "GRAMMAR",
    "CanSpec",
    "Heard",
    "Link",
    "LinkSpec",
    "SerialSpec",
    "ZenohSpec",
    "can_link",
    "parse",
    "serial_link",
    "zenoh_link_from_spec",
]

_LAZY = {"can_link": "can", "serial_link": "serial", "zenoh_link_from_spec": "zenoh"}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f".{module}", __name__), name)
