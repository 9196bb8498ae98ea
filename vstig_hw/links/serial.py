"""Serial links (`serial:` and `kilobot-ohc:` specs): one call to a Link, `serial_link("/dev/ttyUSB0", "epuck4")`.

pyserial and the serial transport are imported when a link is built, not when a spec is parsed.
`framing=xbee` puts a Digi XBee module in API mode behind the port (transports/xbee.py).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from ..tagged import AuthPolicy
from .grammar import bad, check_port, integer, safe_name, split_query, unknown_key
from .link import Link, LinkSpec

if TYPE_CHECKING:
    from ..framing import SerialFraming
    from ..framing.xbee import XBeeFraming
    from ..transports.xbee import XBeeTransport

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "SerialSpec", "parse_ohc", "parse_serial", "serial_link",
           "serial_link_from_spec"]

SERIAL_FRAMINGS = ("cobs8", "epuck4", "kilobot", "xbee")
DEFAULT_BAUD = 115200
OHC_BAUD = 38400  # the Kilobot overhead controller's fixed rate
XBEEMAV_BAUD = 230400  # XbeeMav's module profiles (BD=8)

GRAMMAR = (
    "serial:<port or pyserial URL>[?baud=N&framing=cobs8|epuck4|kilobot&expiry_ticks=N]",
    "serial:<port>?framing=xbee[&api=1|2&dest=<64-bit address, hex>&baud=N]",
    "kilobot-ohc:<port or pyserial URL>",
    "serial:<port>?framing=kilobot&dialect=bittybuzz&deployment=<file.toml>, kilobot-ohc:<port>?dialect=bittybuzz&"
    "deployment=<file.toml>",
    "serial:<port>?framing=xbee&dialect=buzz&deployment=<file.toml>[&api=1|2&baud=N]",
)
EXAMPLES = {
    "serial": ("serial:/dev/ttyUSB0?baud=115200", "serial:socket://localhost:7000?framing=epuck4",
               "serial:/dev/rfcomm0?framing=kilobot",
               "serial:/dev/ttyUSB1?framing=epuck4&expiry_ticks=5"),
    "kilobot-ohc": ("kilobot-ohc:/dev/ttyUSB0", "kilobot-ohc:/dev/ttyUSB0?dialect=bittybuzz&deployment=lab.toml"),
    "bittybuzz": ("serial:/dev/ttyUSB0?framing=kilobot&dialect=bittybuzz&deployment=lab.toml",),
    "xbee": ("serial:/dev/ttyUSB0?framing=xbee&baud=230400", "serial:/dev/ttyUSB0?framing=xbee&api=2",
             "serial:/dev/ttyUSB0?framing=xbee&dest=0013A20040A1B2C3"),
    "rosbuzz": ("serial:/dev/ttyUSB0?framing=xbee&dialect=buzz&deployment=drones.toml",),
}
# For `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "serial": "serial: the query after the last '?' is ours; a pyserial URL (socket://, rfc2217://...) keeps "
              "the keys its handler reads (logging=...), and any other key is a typo. Defaults: baud=115200, "
              "framing=cobs8. A serial link carries one stigmergy: its framings have no stigmergy field. "
              "epuck4's expiry_ticks (default 3) is how many "
              "control periods a message's three words may take to arrive (firmware_spec/SPEC.md 6.2.2).",
    "kilobot-ohc": "kilobot-ohc: transmit only, at the overhead controller's fixed 38400 baud.",
    "bittybuzz": "bittybuzz: Kilobots running BittyBuzz, through a bridge radio (framing=kilobot) or the overhead "
                 "controller; deployment= names the TOML file that maps their string ids and values to our keys "
                 "(firmware_spec/dialects.md section 5).",
    "xbee": "xbee: a Digi XBee module in API mode (AP=1, or api=2 for AP=2) at the module's BD rate (default 9600, "
            "Digi's factory setting); messages go in 0x10 frames broadcast (or to dest=), as many as the module's NP "
            "holds; a 0x90's 64-bit source is its sender (docs/how-to/xbee.md).",
    "rosbuzz": "rosbuzz: ROSBuzz drones on XBee radios, in MISTLab XbeeMav's packets (API mode 1 at 230400 baud unless "
               "api=/baud= say otherwise); deployment= maps their Buzz keys and values to ours; --robot-id 0..255.",
}
_SERIAL_EXAMPLE = EXAMPLES["serial"][0]
_OHC_EXAMPLE = EXAMPLES["kilobot-ohc"][0]


@dataclass(frozen=True, slots=True)
class SerialSpec(LinkSpec):
    port: str
    baud: int = DEFAULT_BAUD
    framing: str = "cobs8"  # cobs8 | epuck4 | kilobot | kilobot-ohc | xbee
    expiry_ticks: int | None = None  # epuck4 only: control periods a fragment waits for the rest
    dialect: str | None = None  # "bittybuzz" (Kilobots) or "buzz" (ROSBuzz over xbee), translated through `deployment`
    deployment: str | None = None  # the deployment TOML file of a dialect link
    api: int = 1  # xbee only: the module's API mode (AP), 1 or 2 (escaped)
    dest: int | None = None  # xbee only: a 64-bit destination instead of broadcast
    auth: AuthPolicy = AuthPolicy.OFF  # auth=: what the link does with untagged messages (SPEC.md 10.6)

    @property
    def kind(self) -> str:
        return "kilobot-ohc" if self.framing == "kilobot-ohc" else "serial"

    @property
    def name(self) -> str:
        tail = self.port.split("://", 1)[-1].split("?", 1)[0].rstrip("/")
        return safe_name(tail.rsplit("/", 1)[-1] or tail)

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` is what a ROSBuzz link sends under, `listen_only` matters to CAN."""
        return serial_link_from_spec(self, name or self.name, robot_id)

    def check_sender(self, robot_id: int) -> None:
        """ValueError when a ROSBuzz link cannot send under `robot_id` (XbeeMav's sysid is one byte)."""
        if self.dialect == "buzz" and not 0 <= robot_id <= 0xFF:
            raise ValueError(f"{robot_id} does not fit serial:{self.port}: ROSBuzz robot ids are 0..255 "
                             "(XbeeMav's sysid is one byte)")


_DIALECT_KEYS = ("dialect", "deployment")
_DIALECT_FRAMINGS = {"bittybuzz": ("kilobot", "kilobot-ohc"), "buzz": ("xbee",)}  # what each dialect rides on


def _dialect(spec: str, example: str, params: dict[str, str], framing: str) -> dict[str, Any]:
    """`dialect=bittybuzz|buzz&deployment=FILE` of a Kilobot or XBee link; {} when the link speaks our own format.
    The file is read when the link is built, as a port is opened then."""
    if "dialect" not in params:
        if "deployment" in params:
            raise bad(spec, "deployment= goes with dialect=bittybuzz or dialect=buzz", example)
        return {}
    dialect = params["dialect"]
    if dialect not in _DIALECT_FRAMINGS:
        raise bad(spec, f"dialect={dialect!r}: a serial link speaks bittybuzz, buzz (or our own format)", example)
    if framing not in _DIALECT_FRAMINGS[dialect]:
        carriers = {"bittybuzz": "Kilobot messages: use framing=kilobot or kilobot-ohc:",
                    "buzz": "XbeeMav's packets on XBee radios: use framing=xbee"}
        raise bad(spec, f"dialect={dialect} rides on {carriers[dialect]}", example)
    if "deployment" not in params:
        raise bad(spec, f"dialect={dialect} needs deployment=<file.toml> (its keys and value types)", example)
    return {"dialect": dialect, "deployment": params["deployment"]}


def _xbee(spec: str, example: str, params: dict[str, str], framing: str) -> dict[str, Any]:
    """`api=1|2` and `dest=<hex>` of an xbee link."""
    found = [key for key in ("api", "dest") if key in params]
    if framing != "xbee":
        if found:
            raise bad(spec, f"{found[0]} is an xbee option, not one of framing={framing}", example)
        return {}
    options: dict[str, Any] = {}
    if "api" in params:
        if params["api"] not in ("1", "2"):
            raise bad(spec, f"api={params['api']!r} must be 1 or 2 (the module's AP setting)", example)
        options["api"] = int(params["api"])
    if "dest" in params:
        text = params["dest"].removeprefix("0x").removeprefix("0X")
        try:
            dest = int(text, 16)
        except ValueError:
            dest = -1
        if not 0 <= dest <= 0xFFFF_FFFF_FFFF_FFFF or len(text) > 16:
            raise bad(spec, f"dest={params['dest']!r} is not a 64-bit address in hex (16 digits, e.g. "
                      "0013A20040A1B2C3; 000000000000FFFF broadcasts)", example)
        options["dest"] = dest
    return options


# The options each of pyserial's own URL handlers reads (pyserial 3.5, serial/urlhandler/): any other key in a
# spec is a typo. A scheme of another handler package (serial.protocol_handler_packages) gets none from a spec.
PYSERIAL_URL_OPTIONS = {
    "loop": ("logging",), "socket": ("logging",), "rfc2217": ("logging", "ign_set_control", "poll_modem", "timeout"),
    "spy": ("file", "color", "raw", "all"), "alt": ("class",), "hwgrep": (), "cp2110": (),
}
_LOG_LEVELS = ("debug", "info", "warning", "error")  # logging=: any other value is a KeyError inside pyserial
_HOST_PORT_SCHEMES = ("socket", "rfc2217")  # their handlers need <host>:<port> (else a TypeError inside pyserial)
# pyserial URL handlers' parameters that open a file for writing: spy:// truncates `file=` as it opens.
_WRITING_PARAMETERS = {"spy": ("file",)}
_SERIAL_KEYS = ("baud", "framing", "expiry_ticks", "api", "dest", *_DIALECT_KEYS)


def _url_scheme(port: str) -> str:
    return port.split("://", 1)[0].lower() if "://" in port else ""


def _split(spec: str, body: str, example: str, ours: tuple[str, ...]) -> tuple[str, dict[str, str]]:
    """Our keys from the query; a pyserial URL keeps the keys its handler reads, any other is a typo."""
    scheme = _url_scheme(body)
    return split_query(spec, body, example, ours, PYSERIAL_URL_OPTIONS.get(scheme, ()),
                       whose=f"pyserial's {scheme}://")


def _port(spec: str, example: str, port: str, ours: tuple[str, ...]) -> str:
    """The port, present and clean; a pyserial URL with only the options (and values) its handler reads, and none
    that would write a file the user did not name to vstig (no --overwrite could guard it, and each reconnect
    would truncate it again). pyserial's handlers turn some of their own errors into a KeyError or TypeError."""
    port = check_port(spec, example, port)
    scheme = _url_scheme(port)
    if scheme not in PYSERIAL_URL_OPTIONS:
        return port
    parts = urlsplit(port)
    url = f"pyserial's {scheme}://"
    # read as pyserial reads it: the query after the first '?', percent-decoded (fil%65= is file=)
    for name, values in parse_qs(parts.query, keep_blank_values=True).items():
        if name not in PYSERIAL_URL_OPTIONS[scheme]:
            raise unknown_key(spec, name, example, ours, PYSERIAL_URL_OPTIONS[scheme], url)
        if name in _WRITING_PARAMETERS.get(scheme, ()):
            raise bad(spec, f"{url} writes {name}=..., and a link never writes files (drop {name}=: {scheme}:// "
                      "then logs to stderr; `vstig record` keeps a capture)", example)
        if name == "logging" and values[0] not in _LOG_LEVELS:
            raise bad(spec, f"{url} logging={values[0]!r} is not one of {'|'.join(_LOG_LEVELS)}", example)
    if scheme in _HOST_PORT_SCHEMES:
        try:
            number = parts.port
        except ValueError:
            number = None
        if not parts.hostname or number is None:
            raise bad(spec, f"{url} needs <host>:<port 0..65535>, e.g. {scheme}://localhost:7000", example)
    return port


def parse_serial(spec: str, body: str) -> SerialSpec:
    """`body` is the spec after `serial:`."""
    example = _SERIAL_EXAMPLE
    port, params = _split(spec, body, example, _SERIAL_KEYS)
    framing = params.get("framing", "cobs8")
    if framing not in SERIAL_FRAMINGS:
        raise bad(spec, f"framing={framing!r} is not one of {'|'.join(SERIAL_FRAMINGS)}", example)
    if framing == "xbee":
        example = EXAMPLES["xbee"][0]
    baud = integer(spec, example, "baud", params["baud"], 1, 100_000_000) if "baud" in params else None
    expiry_ticks = None
    if "expiry_ticks" in params:
        if framing != "epuck4":
            raise bad(spec, f"expiry_ticks is an epuck4 option, not one of framing={framing}", example)
        expiry_ticks = integer(spec, example, "expiry_ticks", params["expiry_ticks"], 1, 254)
    dialect = _dialect(spec, example, params, framing)
    if baud is None:
        baud = _default_baud(framing, dialect.get("dialect"))
    return SerialSpec(port=_port(spec, example, port, _SERIAL_KEYS), baud=baud, framing=framing,
                      expiry_ticks=expiry_ticks, **dialect, **_xbee(spec, example, params, framing))


def _default_baud(framing: str, dialect: str | None) -> int:
    """The line speed a link runs at unless told: its framing's radios' (an XBee's factory 9600, XbeeMav's 230400)."""
    if framing != "xbee":
        return DEFAULT_BAUD
    from ..framing.xbee import XBeeFraming

    return XBEEMAV_BAUD if dialect == "buzz" else XBeeFraming.default_baud


def parse_ohc(spec: str, body: str) -> SerialSpec:
    """`body` is the spec after `kilobot-ohc:`."""
    port, params = _split(spec, body, _OHC_EXAMPLE, _DIALECT_KEYS)
    return SerialSpec(port=_port(spec, _OHC_EXAMPLE, port, _DIALECT_KEYS), baud=OHC_BAUD, framing="kilobot-ohc",
                      **_dialect(spec, _OHC_EXAMPLE, params, "kilobot-ohc"))


def serial_link(port: str, framing: str = "cobs8", baud: int | None = None, *, name: str | None = None,
                connect: bool = True, transport_options: Mapping[str, Any] | None = None,
                **framing_options: Any) -> Link[bytes]:
    """A Link over `port` (a device path or any pyserial URL) speaking `framing`.

    `baud` defaults to the framing's own (38400 for kilobot-ohc, 9600 for xbee, 115200 otherwise).
    `transport_options` go to SerialTransport (parity, stopbits, rtscts, backoff_max...; for xbee
    and xbee-api2, an XBeeTransport: at_timeout too), the other keyword options to the framing
    (e.g. expiry_ticks=5, msg_type=0x42, dest=0x0013A20040A1B2C3).
    With `connect` the port is opened now, so a bad port fails here with a TransportError.
    Unknown framings or options raise ValueError naming them.
    """
    from ..framing import make_serial_framing
    from ..framing.xbee import XBeeFraming
    from ..transports.serial import SerialTransport

    codec = make_serial_framing(framing, **framing_options)
    transport: SerialTransport
    if isinstance(codec, XBeeFraming):
        transport = _xbee_transport(port, baud or codec.default_baud, codec, name, transport_options)
    else:
        transport = SerialTransport(port, baud or codec.default_baud, name=name, preamble=codec.preamble,
                                    **dict(transport_options or {}))
    link: Link[bytes] = Link(name or port, transport, codec)
    if connect:
        link.open()
    return link


def serial_link_from_spec(spec: SerialSpec, name: str, robot_id: int = 0) -> Link[Any]:
    """The link a spec names; `robot_id` is what a ROSBuzz link (dialect=buzz) sends under."""
    if spec.framing == "xbee":
        return _xbee_link(spec, name, robot_id)
    if spec.dialect is not None:
        return _dialect_link(spec, name)
    options: dict[str, Any] = {} if spec.expiry_ticks is None else {"expiry_ticks": spec.expiry_ticks}
    return serial_link(spec.port, spec.framing, spec.baud, name=name, connect=False, **options)


def _xbee_link(spec: SerialSpec, name: str, robot_id: int) -> Link[bytes]:
    """An XBee module behind the port: our messages, or ROSBuzz's through XbeeMav's packets (dialect=buzz)."""
    from ..framing.xbee import BROADCAST, XBeeApi2Framing, XBeeFraming

    dest = BROADCAST if spec.dest is None else spec.dest
    codec: XBeeFraming
    if spec.dialect == "buzz":
        from ..dialects.framing import XbeeMavApi2Framing, XbeeMavFraming
        from ..dialects.mapping import load_deployment

        rosbuzz = XbeeMavApi2Framing if spec.api == 2 else XbeeMavFraming
        codec = rosbuzz(load_deployment(str(spec.deployment)), robot_id, dest)
    else:
        codec = (XBeeApi2Framing if spec.api == 2 else XBeeFraming)(dest)
    return Link(name, _xbee_transport(spec.port, spec.baud, codec, name), codec)


def _xbee_transport(port: str, baud: int, codec: XBeeFraming, name: str | None,
                    options: Mapping[str, Any] | None = None) -> XBeeTransport:
    """The module behind the port, in the framing's API mode; what it says at open sizes the framing's frames."""
    from ..transports.xbee import XBeeTransport

    return XBeeTransport(port, baud, api=2 if codec.escaped else 1, name=name, on_module=codec.use_module,
                         **dict(options or {}))


def _dialect_link(spec: SerialSpec, name: str) -> Link[bytes]:
    """Kilobots running BittyBuzz: the Kilobot framings with a deployment's translator inside."""
    from ..dialects.framing import BittyBuzzKilobotFraming, BittyBuzzOhcFraming
    from ..dialects.mapping import load_deployment
    from ..transports.serial import SerialTransport

    deployment = load_deployment(str(spec.deployment))
    codec: SerialFraming = (BittyBuzzOhcFraming(deployment) if spec.framing == "kilobot-ohc"
                            else BittyBuzzKilobotFraming(deployment))
    return Link(name, SerialTransport(spec.port, spec.baud, name=name, preamble=codec.preamble), codec)
