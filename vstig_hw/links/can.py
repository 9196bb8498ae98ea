"""CAN links (`can:` specs): python-can bus + the vstig CAN framing (firmware_spec/SPEC.md section 6.5).

python-can is imported when a spec is checked or built, not with this module (`vstig links` lists the
grammar without it).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from ..tagged import AuthPolicy
from .grammar import bad, flag, integer, safe_name, split_query
from .link import Link, LinkSpec

if TYPE_CHECKING:
    import can

    from ..framing.can import CanIdScheme

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "CanSpec", "can_link", "can_link_from_spec", "parse_can"]

GRAMMAR = (
    "can:<python-can interface>:<channel>[?bitrate=N&fd=1&id_base=0x...&extended=1&stigmergy=N&filter=0&echo=1"
    "&bus.KEY=VALUE]",
)
EXAMPLES = {
    "can": ("can:socketcan:vcan0", "can:virtual:lab", "can:slcan:/dev/ttyACM0?bitrate=500000",
            "can:socketcan:can0?fd=1&id_base=0x18000000&extended=1",
            "can:socketcan:can0?extended=1&stigmergy=2", "can:socketcan:can0?filter=0",
            "can:socketcand:can0?bus.host=192.168.1.5&bus.port=29536"),
}
# For `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "can": "can: 11-bit IDs (default base 0x600) keep stigmergies apart by id_base (0x000, 0x200, 0x400, "
           "0x600); 29-bit IDs (extended=1) carry stigmergy=0..255 in the ID. Each link hears only its own. "
           "filter=0 turns the kernel/adapter acceptance filter off, so foreign IDs reach vstig-hw and are "
           "counted as drop_unknown_id (a conformance check; costs CPU on a busy bus). A bus is one broadcast "
           "domain, so a bridge sends a PUT it heard there on to its other links only; echo=1 sends it back too "
           "(for a bus whose robots do not all hear each other, e.g. behind radio adapters). bus.KEY=VALUE passes "
           "KEY to python-can's can.Bus (as its tools' --bus-kwargs): bus.host, bus.port for socketcand, "
           "bus.receive_own_messages=true...",
}
_EXAMPLE = EXAMPLES["can"][0]
_IFACE = re.compile(r"[A-Za-z0-9_]+\Z")


@dataclass(frozen=True, slots=True)
class CanSpec(LinkSpec):
    interface: str
    channel: str
    bitrate: int | None = None
    fd: bool = False
    id_base: int | None = None
    extended: bool = False
    stigmergy: int = 0
    kernel_filter: bool = True  # False: every frame reaches us, and foreign IDs count as drop_unknown_id
    echo: bool = False  # True: a PUT heard on this bus is re-broadcast back onto it too (Link.one_domain off)
    bus_options: tuple[tuple[str, Any], ...] = ()  # bus.KEY=VALUE: more keywords for can.Bus (host, port...)
    auth: AuthPolicy = AuthPolicy.OFF  # auth=: what the link does with untagged messages (SPEC.md 10.6)
    capture_medium = "can"  # python-can's log formats

    @property
    def kind(self) -> str:
        return "can"

    @property
    def name(self) -> str:
        """A short, space-free name for status lines and captures."""
        return safe_name(self.channel)

    def scheme(self) -> CanIdScheme:
        """The arbitration-ID scheme these parameters name; ValueError if they name none."""
        from ..framing.can import CanIdScheme

        return CanIdScheme(extended=self.extended, base=self.id_base, stigmergy=self.stigmergy)

    def for_table(self, table: int, listening: tuple[str, ...] = ()) -> LinkSpec:
        """The same bus with `table` in the 29-bit IDs' stigmergy field; 11-bit IDs have none (ValueError)."""
        if not self.extended:
            raise ValueError(f"stigmergy: can:{self.interface}:{self.channel} has 11-bit IDs, which tell tables "
                             "apart only by id_base: add extended=1 to carry several, or join once per id_base")
        return replace(self, stigmergy=table)

    @property
    def reach_note(self) -> str | None:
        if self.interface != "virtual":
            return None
        return (f"can:virtual:{self.channel} is a bus inside this process only: no other program hears it "
                "(vcan or can:udp_multicast: reach other processes)")

    def check_sender(self, robot_id: int) -> None:
        """ValueError when this link's ID scheme has no room for `robot_id` as a sender."""
        max_sender = self.scheme().max_sender
        if robot_id > max_sender:
            raise ValueError(f"{robot_id} does not fit can:{self.interface}:{self.channel}: its "
                             f"{29 if self.extended else 11}-bit IDs carry node ids 0..{max_sender} "
                             "(extended=1 gives 29-bit IDs: 0..65535)")

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` is the sender field a CAN link transmits under."""
        return can_link_from_spec(self, name or self.name, robot_id=robot_id, listen_only=listen_only)


def parse_can(spec: str, body: str) -> CanSpec:
    """`body` is the spec after `can:`."""
    interface, sep, rest = body.partition(":")
    if not sep:
        raise bad(spec, "expected can:<interface>:<channel>", _EXAMPLE)
    if not _IFACE.match(interface):
        raise bad(spec, f"interface {interface!r} is not a python-can interface name", _EXAMPLE)
    channel, params = split_query(spec, rest, _EXAMPLE, ("bitrate", "fd", "id_base", "extended", "stigmergy",
                                                         "filter", "echo"),
                                  open_prefix=_BUS_PREFIX)
    if not channel or any(ch in channel for ch in "\0\n\r "):
        raise bad(spec, f"channel {channel!r} is missing or has spaces", _EXAMPLE)
    extended = flag(spec, _EXAMPLE, "extended", params["extended"]) if "extended" in params else False
    id_base = None
    if "id_base" in params:
        id_base = integer(spec, _EXAMPLE, "id_base", params["id_base"], 0, 0x1FFFFFFF if extended else 0x7FF)
    stigmergy = integer(spec, _EXAMPLE, "stigmergy", params["stigmergy"], 0, 0xFF) if "stigmergy" in params else 0
    if stigmergy and not extended:
        raise bad(spec, f"stigmergy={stigmergy} needs 29-bit IDs (extended=1); on 11-bit IDs give each "
                        "stigmergy its own id_base (0x000, 0x200, 0x400, 0x600)", _EXAMPLE)
    parsed = CanSpec(
        interface=interface,
        channel=channel,
        bitrate=integer(spec, _EXAMPLE, "bitrate", params["bitrate"], 1, 10_000_000) if "bitrate" in params else None,
        fd=flag(spec, _EXAMPLE, "fd", params["fd"]) if "fd" in params else False,
        id_base=id_base,
        extended=extended,
        stigmergy=stigmergy,
        kernel_filter=flag(spec, _EXAMPLE, "filter", params["filter"]) if "filter" in params else True,
        echo=flag(spec, _EXAMPLE, "echo", params["echo"]) if "echo" in params else False,
        bus_options=_bus_options(spec, params),
    )
    try:
        parsed.scheme()  # an id_base the ID scheme has no room for (0x601) is the spec's fault
    except ValueError as error:
        raise bad(spec, str(error), _EXAMPLE) from None
    return parsed


_BUS_PREFIX = "bus."
# Keywords the spec itself sets on the way to can.Bus (and can_link's own parameters).
_OURS_ON_THE_BUS = ("interface", "channel", "bitrate", "fd", "can_filters", "robot_id", "id_base", "extended",
                    "stigmergy", "kernel_filter", "echo", "name")


def _bus_options(spec: str, params: dict[str, str]) -> tuple[tuple[str, Any], ...]:
    """bus.KEY=VALUE pairs as can.Bus keywords; a value reads as python-can's `--bus-kwargs` do (int, float,
    true/false, else text)."""
    options: list[tuple[str, Any]] = []
    for key, text in params.items():
        if not key.startswith(_BUS_PREFIX):
            continue
        name = key[len(_BUS_PREFIX):]
        if name in _OURS_ON_THE_BUS:
            hint = f"give {name}= itself" if name in ("bitrate", "fd") else "it is set from the spec"
            raise bad(spec, f"{key} is not a bus option of its own: {hint}", _EXAMPLE)
        options.append((name, _bus_value(text)))
    return tuple(options)


def _bus_value(text: str) -> Any:
    for convert in (lambda t: int(t, 0), float):
        try:
            return convert(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


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
    from ..framing.can import CanFraming, CanIdScheme
    from ..transports.can import CanTransport

    scheme = CanIdScheme(extended=extended, base=id_base, stigmergy=stigmergy)
    framing = CanFraming(scheme, sender=robot_id, fd=fd)
    filters = scheme.can_filters() if kernel_filter else None
    transport = CanTransport(interface, channel, bitrate=bitrate, fd=fd, can_filters=filters, **bus_options)
    return Link(name or f"{interface}:{channel}", transport, framing, one_domain=not echo)


def can_link_from_spec(spec: CanSpec, name: str, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
    from ..framing.can import LISTENER_ID

    return can_link(spec.interface, spec.channel, robot_id=LISTENER_ID if listen_only else robot_id,
                    bitrate=spec.bitrate, fd=spec.fd, id_base=spec.id_base, extended=spec.extended,
                    stigmergy=spec.stigmergy, kernel_filter=spec.kernel_filter, echo=spec.echo, name=name,
                    **dict(spec.bus_options))
