"""CAN links: python-can bus + the vstig CAN framing (firmware_spec/SPEC.md section 6.5)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import can

from ..framing.can import LISTENER_ID, CanFraming, CanIdScheme
from ..transports.can import CanTransport
from .link import Link

if TYPE_CHECKING:
    from .spec import CanSpec

__all__ = ["can_link", "can_link_from_spec"]


def can_link(
    interface: str,
    channel: str,
    *,
    robot_id: int,
    bitrate: int | None = None,
    fd: bool = False,
    id_base: int | None = None,
    extended: bool = False,
    stigmergy: int = 0,
    kernel_filter: bool = True,
    echo: bool = False,
    name: str | None = None,
    **bus_options: Any,
) -> Link[can.Message]:
    """A CAN link in one call (not yet open: call `.open()`).

    `interface`/`channel`/`bitrate` go to python-can unchanged (socketcan vcan0,
    slcan /dev/ttyACM0, pcan PCAN_USBBUS1, virtual ...); `bus_options` too (e.g.
    `sleep_after_open=0` for slcan). The transport's kernel/hardware filters pass
    only this scheme's IDs; with `kernel_filter=False` every frame reaches the
    framing, which counts foreign IDs as `unknown_id`. A bus is one broadcast domain
    (`Link.one_domain`): an engine gateway does not send a PUT it heard here back here,
    unless `echo` (robots behind adapters that do not all hear each other). Raises ValueError for a bad
    id_base/stigmergy/robot_id.
    """
    scheme = CanIdScheme(extended=extended, base=id_base, stigmergy=stigmergy)
    framing = CanFraming(scheme, sender=robot_id, fd=fd)
    filters = scheme.can_filters() if kernel_filter else None
    transport = CanTransport(interface, channel, bitrate=bitrate, fd=fd, can_filters=filters, **bus_options)
    return Link(name or f"{interface}:{channel}", transport, framing, one_domain=not echo)


def can_link_from_spec(spec: CanSpec, name: str, *, robot_id: int = LISTENER_ID,
                       listen_only: bool = False) -> Link[Any]:
    return can_link(spec.interface, spec.channel, robot_id=LISTENER_ID if listen_only else robot_id,
                    bitrate=spec.bitrate, fd=spec.fd, id_base=spec.id_base, extended=spec.extended,
                    stigmergy=spec.stigmergy, kernel_filter=spec.kernel_filter, echo=spec.echo, name=name,
                    **dict(spec.bus_options))
