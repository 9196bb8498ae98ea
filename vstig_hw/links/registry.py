"""Which module owns each link-spec scheme; a module is imported only when a spec of its scheme is parsed.

As python-can's `BACKENDS` maps an interface name to (module, class), `SCHEMES` maps a scheme to
(module in this package, its parser). Each medium's module owns its spec dataclass, parser, GRAMMAR,
EXAMPLES, NOTES and builder, so a new medium is one module plus one line here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import cache
from importlib import import_module
from types import ModuleType
from typing import cast

from .grammar import bad, take_auth
from .link import LinkSpec

__all__ = ["SCHEMES", "examples", "grammar", "notes", "parse"]

SCHEMES: dict[str, tuple[str, str]] = {
    "can": ("can", "parse_can"),
    "serial": ("serial", "parse_serial"),
    "kilobot-ohc": ("serial", "parse_ohc"),
    "blabbermouth": ("blabbermouth", "parse_blabbermouth"),
    "zenoh": ("zenoh", "parse_zenoh"),
    "ros2": ("ros2", "parse_ros2"),
    "mavlink": ("mavlink", "parse_mavlink"),
}
_ANY_EXAMPLE = "serial:/dev/ttyUSB0?baud=115200"  # for a spec whose scheme names no module


def _module(name: str) -> ModuleType:
    return import_module(f".{name}", __package__)


def parse(spec: str) -> LinkSpec:
    """Parse one link spec; ValueError (one line, with an example) when it is bad."""
    if not isinstance(spec, str):
        raise ValueError(f"a link spec is a string, got {type(spec).__name__}")
    scheme, sep, body = spec.partition(":")
    if not sep or scheme not in SCHEMES:
        raise bad(spec, f"unknown kind {scheme!r}; a spec starts with {', '.join(f'{s}:' for s in SCHEMES)}",
                  _ANY_EXAMPLE)
    module, parser = SCHEMES[scheme]
    body, policy = take_auth(spec, body, _ANY_EXAMPLE.replace("?", "?auth=require&"))
    parsed = cast(Callable[[str, str], LinkSpec], getattr(_module(module), parser))(spec, body)
    return parsed if policy is None else dataclasses.replace(parsed, auth=policy)  # type: ignore[type-var]


def _media() -> list[ModuleType]:
    """Every medium's module, once each, in the order of `SCHEMES` (importing them all: for help text)."""
    return [_module(name) for name in dict.fromkeys(module for module, _ in SCHEMES.values())]


@cache
def grammar() -> tuple[str, ...]:
    """One line per form of spec, for `vstig links`."""
    return tuple(rule for medium in _media() for rule in medium.GRAMMAR)


@cache
def examples() -> dict[str, tuple[str, ...]]:
    """Valid specs by kind (can, serial, kilobot-ohc, bittybuzz...)."""
    return {kind: specs for medium in _media() for kind, specs in medium.EXAMPLES.items()}


@cache
def notes() -> dict[str, str]:
    """One line per kind: what its options mean beyond the grammar."""
    return {kind: note for medium in _media() for kind, note in medium.NOTES.items()}
