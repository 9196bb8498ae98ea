"""Serial links: one call to a Link, `serial_link("/dev/ttyUSB0", "epuck4")`."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from ..framing import SerialFraming, make_serial_framing
from ..transports.serial import SerialTransport
from .link import Link

if TYPE_CHECKING:
    from .spec import SerialSpec

__all__ = ["serial_link", "serial_link_from_spec"]


def serial_link(port: str, framing: str = "cobs8", baud: int | None = None, *, name: str | None = None,
                connect: bool = True, transport_options: Mapping[str, Any] | None = None,
                **framing_options: Any) -> Link[bytes]:
    """A Link over `port` (a device path or any pyserial URL) speaking `framing`.

    `baud` defaults to the framing's own (38400 for kilobot-ohc, 115200 otherwise).
    `transport_options` go to SerialTransport (parity, stopbits, rtscts, backoff_max...),
    the other keyword options to the framing (e.g. expiry_ticks=5, msg_type=0x42).
    With `connect` the port is opened now, so a bad port fails here with a TransportError.
    Unknown framings or options raise ValueError naming them.
    """
    codec = make_serial_framing(framing, **framing_options)
    transport = SerialTransport(port, baud or codec.default_baud, name=name, preamble=codec.preamble,
                                **dict(transport_options or {}))
    link: Link[bytes] = Link(name or port, transport, codec)
    if connect:
        link.open()
    return link


def serial_link_from_spec(spec: SerialSpec, name: str) -> Link[Any]:
    """A serial link never names its sender, so unlike CAN it needs no robot id."""
    if spec.dialect is not None:
        return _dialect_link(spec, name)
    options: dict[str, Any] = {} if spec.expiry_ticks is None else {"expiry_ticks": spec.expiry_ticks}
    return serial_link(spec.port, spec.framing, spec.baud, name=name, connect=False, **options)


def _dialect_link(spec: SerialSpec, name: str) -> Link[bytes]:
    """Kilobots running BittyBuzz: the Kilobot framings with a deployment's translator inside."""
    from ..dialects.framing import BittyBuzzKilobotFraming, BittyBuzzOhcFraming
    from ..dialects.mapping import load_deployment

    deployment = load_deployment(str(spec.deployment))
    codec: SerialFraming = (BittyBuzzOhcFraming(deployment) if spec.framing == "kilobot-ohc"
                            else BittyBuzzKilobotFraming(deployment))
    return Link(name, SerialTransport(spec.port, spec.baud, name=name, preamble=codec.preamble), codec)
