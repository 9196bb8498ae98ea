"""Serial links (`serial:` and `kilobot-ohc:` specs): one call to a Link, `serial_link("/dev/ttyUSB0", "epuck4")`.

pyserial and the serial transport are imported when a link is built, not when a spec is parsed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from .grammar import bad, check_port, integer, safe_name, split_query
from .link import Link

if TYPE_CHECKING:
    from ..framing import SerialFraming

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "SerialSpec", "parse_ohc", "parse_serial", "serial_link",
           "serial_link_from_spec"]

SERIAL_FRAMINGS = ("cobs8", "epuck4", "kilobot")
DEFAULT_BAUD = 115200
OHC_BAUD = 38400  # the Kilobot overhead controller's fixed rate

GRAMMAR = (
    "serial:<port or pyserial URL>[?baud=N&framing=cobs8|epuck4|kilobot&expiry_ticks=N]",
    "kilobot-ohc:<port or pyserial URL>",
    "serial:<port>?framing=kilobot&dialect=bittybuzz&deployment=<file.toml>, kilobot-ohc:<port>?dialect=bittybuzz&"
    "deployment=<file.toml>",
)
EXAMPLES = {
    "serial": ("serial:/dev/ttyUSB0?baud=115200", "serial:socket://localhost:7000?framing=epuck4",
               "serial:/dev/rfcomm0?framing=kilobot",
               "serial:/dev/ttyUSB1?framing=epuck4&expiry_ticks=5"),
    "kilobot-ohc": ("kilobot-ohc:/dev/ttyUSB0", "kilobot-ohc:/dev/ttyUSB0?dialect=bittybuzz&deployment=lab.toml"),
    "bittybuzz": ("serial:/dev/ttyUSB0?framing=kilobot&dialect=bittybuzz&deployment=lab.toml",),
}
# For `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "serial": "serial: the query after the last '?' is ours; keys we do not know stay with a pyserial URL "
              "(socket://, rfc2217://). Defaults: baud=115200, framing=cobs8. A serial link carries one "
              "stigmergy: its framings have no stigmergy field. epuck4's expiry_ticks (default 3) is how many "
              "control periods a message's three words may take to arrive (firmware_spec/SPEC.md 6.2.2).",
    "kilobot-ohc": "kilobot-ohc: transmit only, at the overhead controller's fixed 38400 baud.",
    "bittybuzz": "bittybuzz: Kilobots running BittyBuzz, through a bridge radio (framing=kilobot) or the overhead "
                 "controller; deployment= names the TOML file that maps their string ids and values to our keys "
                 "(firmware_spec/dialects.md section 5).",
}
_SERIAL_EXAMPLE = EXAMPLES["serial"][0]
_OHC_EXAMPLE = EXAMPLES["kilobot-ohc"][0]


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
        return safe_name(tail.rsplit("/", 1)[-1] or tail)

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` and `listen_only` matter only to CAN (same signature as CanSpec)."""
        return serial_link_from_spec(self, name or self.name)


_DIALECT_KEYS = ("dialect", "deployment")


def _dialect(spec: str, example: str, params: dict[str, str], framing: str) -> dict[str, Any]:
    """`dialect=bittybuzz&deployment=FILE` of a Kilobot link; {} when the link speaks our own format.
    The file is read when the link is built, as a port is opened then."""
    if "dialect" not in params:
        if "deployment" in params:
            raise bad(spec, "deployment= goes with dialect=bittybuzz", example)
        return {}
    if params["dialect"] != "bittybuzz":
        raise bad(spec, f"dialect={params['dialect']!r}: a serial link speaks bittybuzz (or our own format)", example)
    if framing not in ("kilobot", "kilobot-ohc"):
        raise bad(spec, "dialect=bittybuzz rides on Kilobot messages: use framing=kilobot or kilobot-ohc:", example)
    if "deployment" not in params:
        raise bad(spec, "dialect=bittybuzz needs deployment=<file.toml> (its keys and value types)", example)
    return {"dialect": "bittybuzz", "deployment": params["deployment"]}


# pyserial URL handlers' parameters that open a file for writing: spy:// truncates `file=` as it opens.
_WRITING_PARAMETERS = {"spy": ("file",)}


def _port(spec: str, example: str, port: str) -> str:
    """The port, present and clean, and no pyserial URL that would write a file the user did not name to vstig
    (no --overwrite could guard it, and each reconnect would truncate it again)."""
    port = check_port(spec, example, port)
    parts = urlsplit(port) if "://" in port else None
    for name in _WRITING_PARAMETERS.get(parts.scheme if parts else "", ()):
        # read as pyserial reads it: the query after the first '?', percent-decoded (fil%65= is file=)
        if parts and name in parse_qs(parts.query, keep_blank_values=True):
            raise bad(spec, f"pyserial's {parts.scheme}:// writes {name}=..., and a link never writes files "
                      f"(drop {name}=: {parts.scheme}:// then logs to stderr; `vstig record` keeps a capture)",
                      example)
    return port


def parse_serial(spec: str, body: str) -> SerialSpec:
    """`body` is the spec after `serial:`."""
    example = _SERIAL_EXAMPLE
    port, params = split_query(spec, body, example, ("baud", "framing", "expiry_ticks", *_DIALECT_KEYS),
                                 "://" in body)
    framing = params.get("framing", "cobs8")
    if framing not in SERIAL_FRAMINGS:
        raise bad(spec, f"framing={framing!r} is not one of {'|'.join(SERIAL_FRAMINGS)}", example)
    baud = integer(spec, example, "baud", params["baud"], 1, 100_000_000) if "baud" in params else DEFAULT_BAUD
    expiry_ticks = None
    if "expiry_ticks" in params:
        if framing != "epuck4":
            raise bad(spec, f"expiry_ticks is an epuck4 option, not one of framing={framing}", example)
        expiry_ticks = integer(spec, example, "expiry_ticks", params["expiry_ticks"], 1, 254)
    return SerialSpec(port=_port(spec, example, port), baud=baud, framing=framing, expiry_ticks=expiry_ticks,
                      **_dialect(spec, example, params, framing))


def parse_ohc(spec: str, body: str) -> SerialSpec:
    """`body` is the spec after `kilobot-ohc:`."""
    port, params = split_query(spec, body, _OHC_EXAMPLE, _DIALECT_KEYS, "://" in body)
    return SerialSpec(port=_port(spec, _OHC_EXAMPLE, port), baud=OHC_BAUD, framing="kilobot-ohc",
                      **_dialect(spec, _OHC_EXAMPLE, params, "kilobot-ohc"))


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
    from ..framing import make_serial_framing
    from ..transports.serial import SerialTransport

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
    from ..transports.serial import SerialTransport

    deployment = load_deployment(str(spec.deployment))
    codec: SerialFraming = (BittyBuzzOhcFraming(deployment) if spec.framing == "kilobot-ohc"
                            else BittyBuzzKilobotFraming(deployment))
    return Link(name, SerialTransport(spec.port, spec.baud, name=name, preamble=codec.preamble), codec)
