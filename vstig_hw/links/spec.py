"""Link specs: one string names a link, as pyserial's URLs name a port.

Grammar (one parser for every command)::

    can:<python-can interface>:<channel>[?bitrate=N&fd=1&id_base=0x600&extended=1&stigmergy=N&filter=0&echo=1
                                         &bus.KEY=V]
    serial:<port or pyserial URL>[?baud=N&framing=cobs8|epuck4|kilobot&expiry_ticks=N]
    kilobot-ohc:<port or pyserial URL>
    serial:<port>?framing=kilobot&dialect=bittybuzz&deployment=<file.toml>   (and kilobot-ohc:<port>?dialect=...)
    blabbermouth:<host>[:port],<host>[:port]...?size=N&deployment=<file.toml>
    zenoh:<swarm>[?mode=peer|client&connect=<endpoint>[,<endpoint>...]&listen=<endpoint>[,...]
                  &config=<zenoh json5 file>&stigmergy=N&scout=1]

The query after the last `?` is ours. A pyserial URL (`socket://h:7000`,
`rfc2217://...`) may carry its own options in the same query: keys we do not
know stay with the URL. A plain device path has no options of its own, so an
unknown key there is a typo and an error.

A bad spec raises ValueError with one line naming the bad part and a valid example.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..framing.can import CanIdScheme
    from .link import Link

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "BlabbermouthSpec", "CanSpec", "LinkSpec", "SerialSpec", "ZenohSpec",
           "parse"]

SERIAL_FRAMINGS = ("cobs8", "epuck4", "kilobot")
DEFAULT_BAUD = 115200
OHC_BAUD = 38400  # the Kilobot overhead controller's fixed rate
KH4_PORT = 24580  # the port bzzkh4 listens on (BuzzKH4 buzz_utility.c)

GRAMMAR = (
    "can:<python-can interface>:<channel>[?bitrate=N&fd=1&id_base=0x...&extended=1&stigmergy=N&filter=0&echo=1"
    "&bus.KEY=VALUE]",
    "serial:<port or pyserial URL>[?baud=N&framing=cobs8|epuck4|kilobot&expiry_ticks=N]",
    "kilobot-ohc:<port or pyserial URL>",
    "serial:<port>?framing=kilobot&dialect=bittybuzz&deployment=<file.toml>, kilobot-ohc:<port>?dialect=bittybuzz&"
    "deployment=<file.toml>",
    "blabbermouth:<host>[:port],<host>[:port]...?size=N&deployment=<file.toml>",
    "zenoh:<swarm>[?mode=peer|client&connect=<endpoint>[,...]&listen=<endpoint>[,...]&config=<zenoh json5 file>"
    "&stigmergy=N&scout=0|1]",
)
EXAMPLES = {
    "can": ("can:socketcan:vcan0", "can:virtual:lab", "can:slcan:/dev/ttyACM0?bitrate=500000",
            "can:socketcan:can0?fd=1&id_base=0x18000000&extended=1",
            "can:socketcan:can0?extended=1&stigmergy=2", "can:socketcan:can0?filter=0",
            "can:socketcand:can0?bus.host=192.168.1.5&bus.port=29536"),
    "serial": ("serial:/dev/ttyUSB0?baud=115200", "serial:socket://localhost:7000?framing=epuck4",
               "serial:/dev/rfcomm0?framing=kilobot",
               "serial:/dev/ttyUSB1?framing=epuck4&expiry_ticks=5"),
    "kilobot-ohc": ("kilobot-ohc:/dev/ttyUSB0", "kilobot-ohc:/dev/ttyUSB0?dialect=bittybuzz&deployment=lab.toml"),
    "bittybuzz": ("serial:/dev/ttyUSB0?framing=kilobot&dialect=bittybuzz&deployment=lab.toml",),
    "blabbermouth": ("blabbermouth:192.168.1.101,192.168.1.102,192.168.1.103?size=100&deployment=lab.toml",
                     "blabbermouth:k01.lab:24580,k02.lab:24580?size=64&deployment=kheperas.toml"),
    "zenoh": ("zenoh:lab", "zenoh:lab?listen=tcp/0.0.0.0:7447&config=lab.json5",
              "zenoh:lab?connect=tcp/10.0.0.5:7447",
              "zenoh:lab?mode=client&connect=tls/router.lab:7447&config=lab.json5",
              "zenoh:lab?scout=1&stigmergy=2"),
}
# One line per kind for `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "can": "can: 11-bit IDs (default base 0x600) keep stigmergies apart by id_base (0x000, 0x200, 0x400, "
           "0x600); 29-bit IDs (extended=1) carry stigmergy=0..255 in the ID. Each link hears only its own. "
           "filter=0 turns the kernel/adapter acceptance filter off, so foreign IDs reach vstig-hw and are "
           "counted as drop_unknown_id (a conformance check; costs CPU on a busy bus). A bus is one broadcast "
           "domain, so a bridge sends a PUT it heard there on to its other links only; echo=1 sends it back too "
           "(for a bus whose robots do not all hear each other, e.g. behind radio adapters). bus.KEY=VALUE passes "
           "KEY to python-can's can.Bus (as its tools' --bus-kwargs): bus.host, bus.port for socketcand, "
           "bus.receive_own_messages=true...",
    "serial": "serial: the query after the last '?' is ours; keys we do not know stay with a pyserial URL "
              "(socket://, rfc2217://). Defaults: baud=115200, framing=cobs8. A serial link carries one "
              "stigmergy: its framings have no stigmergy field. epuck4's expiry_ticks (default 3) is how many "
              "control periods a message's three words may take to arrive (firmware_spec/SPEC.md 6.2.2).",
    "kilobot-ohc": "kilobot-ohc: transmit only, at the overhead controller's fixed 38400 baud.",
    "bittybuzz": "bittybuzz: Kilobots running BittyBuzz, through a bridge radio (framing=kilobot) or the overhead "
                 "controller; deployment= names the TOML file that maps their string ids and values to our keys "
                 "(firmware_spec/dialects.md section 5).",
    "blabbermouth": "blabbermouth: replaces MISTLab's blabbermouth relay for Khepera IV robots running BuzzKH4 "
                    "(bzzkh4 tcp <size> ...): connects to each robot (port 24580 unless given), relays every "
                    "robot's frame to all the others, and sends our own under --robot-id. size= must be the "
                    "robots' msg_size; deployment= maps their Buzz keys and values to ours.",
    "zenoh": "zenoh: gateways on many PCs as one swarm (key vstig/<swarm>/<stigmergy>/<gateway id>). Closed by "
             "default: listens on a free loopback port (printed once open), no multicast scouting; listen=, connect= "
             "or scout=1 open it, config= passes a Zenoh config file (TLS, user/password, routers) through.",
}
_IFACE = re.compile(r"[A-Za-z0-9_]+\Z")
_NAME_UNSAFE = re.compile(r"[^A-Za-z0-9._:-]+")


@dataclass(frozen=True, slots=True)
class CanSpec:
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

    @property
    def kind(self) -> str:
        return "can"

    @property
    def name(self) -> str:
        """A short, space-free name for status lines and captures."""
        return _safe_name(self.channel)

    def scheme(self) -> CanIdScheme:
        """The arbitration-ID scheme these parameters name; ValueError if they name none."""
        from ..framing.can import CanIdScheme

        return CanIdScheme(extended=self.extended, base=self.id_base, stigmergy=self.stigmergy)

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` is the sender field a CAN link transmits under."""
        from .can import can_link_from_spec

        return can_link_from_spec(self, name or self.name, robot_id=robot_id, listen_only=listen_only)


@dataclass(frozen=True, slots=True)
class SerialSpec:
    port: str
    baud: int = DEFAULT_BAUD
    framing: str = "cobs8"  # cobs8 | epuck4 | kilobot | kilobot-ohc
    expiry_ticks: int | None = None  # epuck4 only: control periods a fragment waits for the rest
    dialect: str | None = None  # "bittybuzz": the robots speak BittyBuzz, translated through `deployment`
    deployment: str | None = None  # the deployment TOML file of a dialect link

    @property
    def kind(self) -> str:
        return "kilobot-ohc" if self.framing == "kilobot-ohc" else "serial"

    @property
    def name(self) -> str:
        tail = self.port.split("://", 1)[-1].split("?", 1)[0].rstrip("/")
        return _safe_name(tail.rsplit("/", 1)[-1] or tail)

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` and `listen_only` matter only to CAN (same signature as CanSpec)."""
        from .serial import serial_link_from_spec

        return serial_link_from_spec(self, name or self.name)


@dataclass(frozen=True, slots=True)
class BlabbermouthSpec:
    robots: tuple[tuple[str, int], ...]
    size: int
    deployment: str

    @property
    def kind(self) -> str:
        return "blabbermouth"

    @property
    def name(self) -> str:
        return "blabbermouth"

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); our frames go out under `robot_id` (a sniffer sends none, but relays)."""
        from .blabbermouth import blabbermouth_link_from_spec

        return blabbermouth_link_from_spec(self, name or self.name, robot_id)


@dataclass(frozen=True, slots=True)
class ZenohSpec:
    swarm: str
    mode: str | None = None  # None: the config file's, else peer
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config: str | None = None
    stigmergy: int = 0
    scout: bool | None = None  # None: the config file's, else off
    block: bool = False  # Zenoh congestion control BLOCK instead of DROP: set by commands that must not lose a sample

    @property
    def kind(self) -> str:
        return "zenoh"

    @property
    def name(self) -> str:
        return _safe_name(f"zenoh-{self.swarm}")

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` names this gateway in the key space (vstig/<swarm>/<stig>/<id>)."""
        from ..extras import require

        require("zenoh", "a zenoh: link")  # before any link of the command opens
        from .zenoh import zenoh_link_from_spec

        return zenoh_link_from_spec(self, name or self.name, robot_id=robot_id, listen_only=listen_only)


LinkSpec = CanSpec | SerialSpec | BlabbermouthSpec | ZenohSpec


def _safe_name(text: str) -> str:
    return _NAME_UNSAFE.sub("_", text).strip("_") or "link"


def _bad(spec: str, problem: str, scheme: str = "") -> ValueError:
    example = EXAMPLES.get(scheme, EXAMPLES["serial"])[0] if scheme else "serial:/dev/ttyUSB0?baud=115200"
    return ValueError(f"bad link spec {spec!r}: {problem} (e.g. {example})")


def _query(spec: str, body: str, scheme: str, ours: tuple[str, ...], is_url: bool,
           open_prefix: str | None = None) -> tuple[str, dict[str, str]]:
    """Split `body` at its last '?' into (rest, our params); foreign keys stay on a URL.

    Keys starting with `open_prefix` are ours too, whatever follows it (passed on as they are).
    """
    if "?" not in body:
        return body, {}
    rest, query = body.rsplit("?", 1)
    params: dict[str, str] = {}
    foreign: list[str] = []
    for item in query.split("&"):
        key, sep, value = item.partition("=")
        if key in ours or (open_prefix and key.startswith(open_prefix) and len(key) > len(open_prefix)):
            if not sep or not value:
                raise _bad(spec, f"parameter {key!r} needs a value ({key}=...)", scheme)
            if key in params:
                raise _bad(spec, f"parameter {key!r} given twice", scheme)
            params[key] = value
        elif is_url and item:
            foreign.append(item)
        else:
            raise _bad(spec, f"unknown parameter {item!r} (known: {', '.join(ours) or 'none'})", scheme)
    if foreign:
        rest = f"{rest}?{'&'.join(foreign)}"
    return rest, params


def _int(spec: str, scheme: str, key: str, text: str, low: int, high: int) -> int:
    try:
        number = int(text, 0)
    except ValueError:
        raise _bad(spec, f"{key}={text!r} is not an integer", scheme) from None
    if not low <= number <= high:
        raise _bad(spec, f"{key}={text} is outside {low}..{high:#x}" if key == "id_base"
                   else f"{key}={text} is outside {low}..{high}", scheme)
    return number


def _flag(spec: str, scheme: str, key: str, text: str) -> bool:
    if text not in ("0", "1"):
        raise _bad(spec, f"{key}={text!r} must be 0 or 1", scheme)
    return text == "1"


def _port(spec: str, scheme: str, port: str) -> str:
    if not port or port.isspace():
        raise _bad(spec, "the port is missing", scheme)
    if any(ch in port for ch in "\0\n\r"):
        raise _bad(spec, "the port contains a control character", scheme)
    return port


def _parse_can(spec: str, body: str) -> CanSpec:
    interface, sep, rest = body.partition(":")
    if not sep:
        raise _bad(spec, "expected can:<interface>:<channel>", "can")
    if not _IFACE.match(interface):
        raise _bad(spec, f"interface {interface!r} is not a python-can interface name", "can")
    channel, params = _query(spec, rest, "can", ("bitrate", "fd", "id_base", "extended", "stigmergy", "filter",
                                                     "echo"),
                             False, open_prefix=_BUS_PREFIX)
    if not channel or any(ch in channel for ch in "\0\n\r "):
        raise _bad(spec, f"channel {channel!r} is missing or has spaces", "can")
    extended = _flag(spec, "can", "extended", params["extended"]) if "extended" in params else False
    id_base = None
    if "id_base" in params:
        id_base = _int(spec, "can", "id_base", params["id_base"], 0, 0x1FFFFFFF if extended else 0x7FF)
    stigmergy = _int(spec, "can", "stigmergy", params["stigmergy"], 0, 0xFF) if "stigmergy" in params else 0
    if stigmergy and not extended:
        raise _bad(spec, f"stigmergy={stigmergy} needs 29-bit IDs (extended=1); on 11-bit IDs give each "
                         "stigmergy its own id_base (0x000, 0x200, 0x400, 0x600)", "can")
    parsed = CanSpec(
        interface=interface,
        channel=channel,
        bitrate=_int(spec, "can", "bitrate", params["bitrate"], 1, 10_000_000) if "bitrate" in params else None,
        fd=_flag(spec, "can", "fd", params["fd"]) if "fd" in params else False,
        id_base=id_base,
        extended=extended,
        stigmergy=stigmergy,
        kernel_filter=_flag(spec, "can", "filter", params["filter"]) if "filter" in params else True,
        echo=_flag(spec, "can", "echo", params["echo"]) if "echo" in params else False,
        bus_options=_bus_options(spec, params),
    )
    try:
        parsed.scheme()  # an id_base the ID scheme has no room for (0x601) is the spec's fault
    except ValueError as error:
        raise _bad(spec, str(error), "can") from None
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
            raise _bad(spec, f"{key} is not a bus option of its own: {hint}", "can")
        options.append((name, _bus_value(text)))
    return tuple(options)


def _bus_value(text: str) -> Any:
    for convert in (lambda t: int(t, 0), float):
        try:
            return convert(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


_DIALECT_KEYS = ("dialect", "deployment")


def _dialect(spec: str, scheme: str, params: dict[str, str], framing: str) -> dict[str, Any]:
    """`dialect=bittybuzz&deployment=FILE` of a Kilobot link; {} when the link speaks our own format.
    The file is read when the link is built, as a port is opened then."""
    if "dialect" not in params:
        if "deployment" in params:
            raise _bad(spec, "deployment= goes with dialect=bittybuzz", scheme)
        return {}
    if params["dialect"] != "bittybuzz":
        raise _bad(spec, f"dialect={params['dialect']!r}: a serial link speaks bittybuzz (or our own format)", scheme)
    if framing not in ("kilobot", "kilobot-ohc"):
        raise _bad(spec, "dialect=bittybuzz rides on Kilobot messages: use framing=kilobot or kilobot-ohc:", scheme)
    if "deployment" not in params:
        raise _bad(spec, "dialect=bittybuzz needs deployment=<file.toml> (its keys and value types)", scheme)
    return {"dialect": "bittybuzz", "deployment": params["deployment"]}


def _parse_serial(spec: str, body: str) -> SerialSpec:
    port, params = _query(spec, body, "serial", ("baud", "framing", "expiry_ticks", *_DIALECT_KEYS), "://" in body)
    framing = params.get("framing", "cobs8")
    if framing not in SERIAL_FRAMINGS:
        raise _bad(spec, f"framing={framing!r} is not one of {'|'.join(SERIAL_FRAMINGS)}", "serial")
    baud = _int(spec, "serial", "baud", params["baud"], 1, 100_000_000) if "baud" in params else DEFAULT_BAUD
    expiry_ticks = None
    if "expiry_ticks" in params:
        if framing != "epuck4":
            raise _bad(spec, f"expiry_ticks is an epuck4 option, not one of framing={framing}", "serial")
        expiry_ticks = _int(spec, "serial", "expiry_ticks", params["expiry_ticks"], 1, 254)
    return SerialSpec(port=_port(spec, "serial", port), baud=baud, framing=framing, expiry_ticks=expiry_ticks,
                      **_dialect(spec, "serial", params, framing))


def _parse_ohc(spec: str, body: str) -> SerialSpec:
    port, params = _query(spec, body, "kilobot-ohc", _DIALECT_KEYS, "://" in body)
    return SerialSpec(port=_port(spec, "kilobot-ohc", port), baud=OHC_BAUD, framing="kilobot-ohc",
                      **_dialect(spec, "kilobot-ohc", params, "kilobot-ohc"))


def _parse_blabbermouth(spec: str, body: str) -> BlabbermouthSpec:
    addresses, params = _query(spec, body, "blabbermouth", ("size", "deployment"), False)
    robots = []
    for address in addresses.split(","):
        host, sep, port = address.strip().rpartition(":") if ":" in address else (address.strip(), "", "")
        if not host or any(ch in host for ch in "\0\n\r /?&"):
            raise _bad(spec, f"robot address {address!r} is not host[:port]", "blabbermouth")
        robots.append((host, _int(spec, "blabbermouth", "port", port, 1, 65535) if sep else KH4_PORT))
    if "size" not in params or "deployment" not in params:
        raise _bad(spec, "size=N (the robots' msg_size) and deployment=<file.toml> are both needed", "blabbermouth")
    return BlabbermouthSpec(tuple(robots), _int(spec, "blabbermouth", "size", params["size"], 5, 65535),
                            params["deployment"])


_ZENOH_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream", "unixpipe", "vsock", "serial")


def _endpoints(spec: str, key: str, text: str) -> tuple[str, ...]:
    endpoints = tuple(text.split(","))
    for endpoint in endpoints:
        protocol, sep, address = endpoint.partition("/")
        if not sep or not address or any(ch.isspace() for ch in endpoint):
            raise _bad(spec, f"{key}={endpoint!r} is not a Zenoh endpoint <protocol>/<address> "
                             "(e.g. tcp/10.0.0.5:7447)", "zenoh")
        if protocol not in _ZENOH_PROTOCOLS:
            raise _bad(spec, f"{key}={endpoint!r}: unknown protocol {protocol!r} "
                             f"(known: {', '.join(_ZENOH_PROTOCOLS)})", "zenoh")
    return endpoints


def _parse_zenoh(spec: str, body: str) -> ZenohSpec:
    from ..framing.zenoh import MAX_STIGMERGY, check_swarm  # the key space's owner; loaded only for zenoh specs

    swarm, params = _query(spec, body, "zenoh", ("mode", "connect", "listen", "config", "stigmergy", "scout"), False)
    try:
        check_swarm(swarm)
    except ValueError as error:
        raise _bad(spec, str(error), "zenoh") from None
    mode = params.get("mode")
    if mode is not None and mode not in ("peer", "client"):
        raise _bad(spec, f"mode={mode!r} must be peer or client", "zenoh")
    connect = _endpoints(spec, "connect", params["connect"]) if "connect" in params else ()
    listen = _endpoints(spec, "listen", params["listen"]) if "listen" in params else ()
    if mode == "client" and listen:
        raise _bad(spec, "a client does not listen: drop listen= or use mode=peer", "zenoh")
    if mode == "client" and not connect and "config" not in params:
        raise _bad(spec, "a client needs connect=<router endpoint> (or a config= file naming one)", "zenoh")
    config = params.get("config")
    if config is not None and any(ch in config for ch in "\0\n\r"):
        raise _bad(spec, "the config path contains a control character", "zenoh")
    return ZenohSpec(
        swarm=swarm,
        mode=mode,
        connect=connect,
        listen=listen,
        config=config,
        stigmergy=_int(spec, "zenoh", "stigmergy", params["stigmergy"], 0, MAX_STIGMERGY)
        if "stigmergy" in params else 0,
        scout=_flag(spec, "zenoh", "scout", params["scout"]) if "scout" in params else None,
    )


_SCHEMES: dict[str, Callable[[str, str], LinkSpec]] = {
    "can": _parse_can, "serial": _parse_serial, "kilobot-ohc": _parse_ohc, "blabbermouth": _parse_blabbermouth,
    "zenoh": _parse_zenoh,
}


def parse(spec: str) -> LinkSpec:
    """Parse one link spec; ValueError (one line, with an example) when it is bad."""
    if not isinstance(spec, str):
        raise ValueError(f"a link spec is a string, got {type(spec).__name__}")
    scheme, sep, body = spec.partition(":")
    if not sep or scheme not in _SCHEMES:
        raise _bad(spec, f"unknown kind {scheme!r}; a spec starts with {', '.join(f'{s}:' for s in _SCHEMES)}")
    return _SCHEMES[scheme](spec, body)
