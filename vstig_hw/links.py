"""Build a Link from a parsed spec, through the serial and CAN links' own constructors."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .link import Link
from .transports.base import TransportError

if TYPE_CHECKING:
    from .linkspec import CanSpec, SerialSpec

__all__ = ["can_link_from_spec", "serial_link_from_spec"]


def can_link_from_spec(spec: CanSpec, name: str, *, listen_only: bool = False) -> Link[Any]:
    raise TransportError(f"{name}: CAN links are not available in this build")


def serial_link_from_spec(spec: SerialSpec, name: str, *, listen_only: bool = False) -> Link[Any]:
    raise TransportError(f"{name}: serial links are not available in this build")
