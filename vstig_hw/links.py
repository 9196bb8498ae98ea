"""Build Links and framings from parsed specs, through the serial and CAN links' own constructors."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .link import Link

if TYPE_CHECKING:
    from .framing.can import CanFraming
    from .linkspec import CanSpec, SerialSpec

__all__ = ["can_framing", "can_framing_for", "can_link_from_spec", "serial_link_from_spec"]

LISTENER_ID = 0  # the CAN sender field of a link that never transmits (sniff, record)


def can_link_from_spec(spec: CanSpec, name: str, *, robot_id: int = LISTENER_ID,
                       listen_only: bool = False) -> Link[Any]:
    from .framing.can import can_link  # imported here: commands load only the media they use

    return can_link(spec.interface, spec.channel, robot_id=LISTENER_ID if listen_only else robot_id,
                    bitrate=spec.bitrate, fd=spec.fd, id_base=spec.id_base, extended=spec.extended, name=name)


def serial_link_from_spec(spec: SerialSpec, name: str) -> Link[Any]:
    """A serial link never names its sender, so unlike CAN it needs no robot id."""
    from .serial_link import serial_link

    return serial_link(spec.port, spec.framing, spec.baud, name=name, connect=False)


def can_framing_for(robot_id: int, id_base: int | None = None, extended: bool = False) -> CanFraming:
    """The CAN framing a node with this id transmits under (and decodes every sender with)."""
    from .framing.can import CanFraming, CanIdScheme

    return CanFraming(CanIdScheme(extended=extended, base=id_base), sender=robot_id)


def can_framing(id_base: int | None = None, extended: bool = False) -> CanFraming:
    """A CAN framing that decodes what any sender put on a bus with this ID scheme."""
    return can_framing_for(LISTENER_ID, id_base, extended)
