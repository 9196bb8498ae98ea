"""Links: one transport plus one framing, the unit the gateway wires together.

This package is the one place links are assembled:

- `link`: `Link` and `Heard`, the medium-independent unit, and `LinkSpec`, what every parsed spec offers
  (`kind`, `name`, `build(...)`);
- `grammar`: what every spec shares (`<scheme>:<body>?key=value&...`) and its one-line errors;
- `registry`: scheme -> owning module; `parse("can:socketcan:vcan0")` imports only that module;
- one module per medium (`can`, `serial` with `kilobot-ohc:`, `blabbermouth`, `zenoh`, `ros2`), each owning its spec
  dataclass, parser, defaults, GRAMMAR/EXAMPLES/NOTES for `vstig links`, and its builder. No medium's module
  imports another's.

Framings stay pure: none of them imports a transport or a link. A medium's module imports its library
(python-can, pyserial, zenoh, rclpy) and its transport only when a link is built (python-can also when a CAN spec
is checked), so a command imports only the media it opens.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from .link import Heard, Link, LinkSpec
from .registry import examples, grammar, notes, parse

__all__ = [
    "Heard",
    "Link",
    "LinkSpec",
    "can_link",
    "examples",
    "grammar",
    "notes",
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
