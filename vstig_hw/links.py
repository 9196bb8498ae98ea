"""Build Links and framings from parsed specs, through the serial and CAN links' own constructors."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .link import Link
from .transports.base import TransportError

if TYPE_CHECKING:
    from .linkspec import CanSpec, SerialSpec

__all__ = ["can_framing", "can_link_from_spec", "serial_framing", "serial_link_from_spec"]

LISTENER_ID = 0  # the CAN sender field a listen-only link would use (it never transmits)


def _module(name: str) -> Any:
    # Imported by name so the gateway loads only the media a command uses.
    try:
        return importlib.import_module(f"vstig_hw.{name}")
    except ImportError as error:
        raise TransportError(f"vstig_hw.{name} is missing from this install ({error})") from None


def can_link_from_spec(spec: CanSpec, name: str, *, robot_id: int = LISTENER_ID,
                       listen_only: bool = False) -> Link[Any]:
    link: Link[Any] = _module("framing.can").can_link(
        spec.interface, spec.channel, robot_id=robot_id if not listen_only else LISTENER_ID,
        bitrate=spec.bitrate, fd=spec.fd, id_base=spec.id_base, extended=spec.extended, name=name,
    )
    return link


def serial_link_from_spec(spec: SerialSpec, name: str, *, robot_id: int = LISTENER_ID,
                          listen_only: bool = False) -> Link[Any]:
    link: Link[Any] = _module("serial_link").serial_link(spec.port, spec.framing, spec.baud, name=name,
                                                         connect=False)
    return link


def can_framing(id_base: int | None = None, extended: bool = False, fd: bool = False) -> Any:
    """A CAN framing that decodes what any sender put on a bus with this ID scheme."""
    can = _module("framing.can")
    return can.CanFraming(can.CanIdScheme(extended=extended, base=id_base), sender=LISTENER_ID, fd=fd)


def can_framing_for(robot_id: int, id_base: int | None = None, extended: bool = False) -> Any:
    """The CAN framing a robot with this id transmits and receives with."""
    can = _module("framing.can")
    return can.CanFraming(can.CanIdScheme(extended=extended, base=id_base), sender=robot_id)


def serial_framing(name: str) -> Any:
    return _module("framing").make_serial_framing(name)
