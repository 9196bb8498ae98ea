"""MAVLink links (`mavlink:` specs): a drone swarm's telemetry radios, or its MAVLink router, as one link.

    mavlink:serial:/dev/ttyUSB0?baud=57600&air_rate=64000   a SiK / RFD900 radio on a UART
    mavlink:udpin:127.0.0.1:14560                           listen; send to whoever spoke lately
    mavlink:udpout:127.0.0.1:14550                          send to a router (MAVProxy, mavlink-router)

Our messages travel in MAVLink 2 TUNNEL messages (framing/mavlink.py, SPEC.md 6.10) from the gateway's own
(sysid, compid): sysid= or --robot-id (1..255), compid= or 191 (an onboard computer). key=FILE signs what the
link sends and refuses what is not signed with the same key; the file holds 64 hex digits (the 32-byte key) or
a passphrase whose SHA-256 is the key (as MAVProxy's `signing setup` and QGroundControl make it), and must not be
readable by group or others. A link without a key logs the exposure warning once when built: anyone on the
radio or network can write the swarm.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

from ..inputs import InputFileError, read_regular
from ..tagged import AuthPolicy
from .grammar import bad, check_port, integer, split_query
from .link import Link, LinkSpec

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "MavlinkSpec", "mavlink_link_from_spec", "parse_mavlink", "read_key"]

log = logging.getLogger(__name__)

SIK_AIR_RATE = 64000  # a SiK radio's factory AIR_SPEED (64 kbit/s)
_KEYS = ("baud", "air_rate", "sysid", "compid", "target", "key", "link_id")
GRAMMAR = (
    "mavlink:serial:<port>[?baud=N&air_rate=BITS_PER_S&sysid=1..255&compid=1..255&target=0..255&key=FILE"
    "&link_id=0..255]",
    "mavlink:udpin:<host>:<port>[?air_rate=...&sysid=...&compid=...&target=...&key=FILE&link_id=...]",
    "mavlink:udpout:<host>:<port>[?air_rate=...&sysid=...&compid=...&target=...&key=FILE&link_id=...]",
)
EXAMPLES = {
    "mavlink": ("mavlink:serial:/dev/ttyUSB0?baud=57600", "mavlink:serial:/dev/ttyUSB0?air_rate=64000&key=swarm.key",
                "mavlink:udpout:127.0.0.1:14550", "mavlink:udpin:127.0.0.1:14560?sysid=12"),
}
NOTES = {
    "mavlink": "mavlink: our messages in MAVLink 2 TUNNEL messages (payload_type 46449), 16 to a TUNNEL, broadcast "
               "(or to target=), from sysid= (default --robot-id, 1..255) and compid= (default 191); HEARTBEATs "
               "once a second as an onboard controller. serial: defaults baud=57600, air_rate=64000 (a SiK radio's "
               "AIR_SPEED): the link sends at most half the air rate. udpin listens and sends to every address heard "
               "in the last 10 s (at most 8); "
               "udpout sends to a router (MAVProxy, mavlink-router). key=FILE signs and checks every frame "
               "(docs/how-to/mavlink.md). With auth=require or prefer, entries go with their writers' tags in TUNNELs "
               "of payload_type 46450 (docs/how-to/auth.md).",
}
_EXAMPLE = EXAMPLES["mavlink"][0]
_KEY_MAX_BYTES = 4096


@dataclass(frozen=True, slots=True)
class MavlinkSpec(LinkSpec):
    medium: str  # serial | udpin | udpout
    where: str  # the port, or host:port
    baud: int = 57600
    air_rate: int | None = None
    sysid: int | None = None  # None: the gateway's robot id
    compid: int = 191
    target: int = 0
    key: str | None = None  # a key file
    link_id: int = 0
    auth: AuthPolicy = AuthPolicy.OFF  # auth=: what the link does with untagged messages (SPEC.md 10.6)

    @property
    def kind(self) -> str:
        return "mavlink"

    @property
    def name(self) -> str:
        from .grammar import safe_name

        tail = self.where.rsplit("/", 1)[-1] if self.medium == "serial" else self.where
        return safe_name(f"mavlink-{tail}")

    def check_sender(self, robot_id: int) -> None:
        """ValueError when the link has no sysid= and `robot_id` is no MAVLink sysid (1..255)."""
        if self.sysid is None and not 1 <= robot_id <= 255:
            raise ValueError(f"{robot_id} is no MAVLink sysid for mavlink:{self.medium}:{self.where}: give "
                             "--robot-id 1..255 or sysid= in the spec")

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        return mavlink_link_from_spec(self, name or self.name, robot_id=robot_id, listen_only=listen_only)


def parse_mavlink(spec: str, body: str) -> MavlinkSpec:
    """`body` is the spec after `mavlink:`."""
    medium, sep, rest = body.partition(":")
    if not sep or medium not in ("serial", "udpin", "udpout"):
        raise bad(spec, f"a mavlink link goes over serial:, udpin: or udpout:, not {medium!r}", _EXAMPLE)
    where, params = split_query(spec, rest, _EXAMPLE, _KEYS)
    options: dict[str, Any] = {}
    if medium == "serial":
        check_port(spec, _EXAMPLE, where)
        options["air_rate"] = SIK_AIR_RATE
    else:
        host, colon, port = where.rpartition(":")
        if not colon or not host or any(ch in host for ch in "\0\n\r /?&"):
            raise bad(spec, f"{medium} needs <host>:<port>, e.g. {medium}:127.0.0.1:14550", _EXAMPLE)
        integer(spec, _EXAMPLE, "port", port, 1, 65535)
        if "baud" in params:
            raise bad(spec, "baud= is for mavlink:serial:, not a UDP link", _EXAMPLE)
    limits = {"baud": (1, 100_000_000), "air_rate": (1000, 100_000_000), "sysid": (1, 255), "compid": (1, 255),
              "target": (0, 255), "link_id": (0, 255)}
    for key, (low, high) in limits.items():
        if key in params:
            options[key] = integer(spec, _EXAMPLE, key, params[key], low, high)
    if "key" in params:
        options["key"] = params["key"]
    return MavlinkSpec(medium, where, **options)


def read_key(path: str) -> bytes:
    """The 32-byte signing key in `path`: 64 hex digits, or a passphrase (its SHA-256); InputFileError naming it
    when the file is not a small regular file, is readable by group or others, or holds nothing."""
    import hashlib

    what = "the MAVLink signing key file"
    data = read_regular(path, _KEY_MAX_BYTES, what, private=True)  # a secret: refused if others may read it
    text = data.decode("utf-8", "replace").strip()
    if not text:
        raise InputFileError(f"{path}: {what} is empty (64 hex digits, or a passphrase)")
    if len(text) == 64 and all(ch in "0123456789abcdefABCDEF" for ch in text):
        return bytes.fromhex(text)
    return hashlib.sha256(text.splitlines()[0].encode("utf-8")).digest()


def mavlink_link_from_spec(spec: MavlinkSpec, name: str, *, robot_id: int = 0,
                           listen_only: bool = False) -> Link[bytes]:
    """A MAVLink link (not yet open) sending as (sysid, compid); a listen-only one sends no HEARTBEATs."""
    from ..framing.mavlink import MavlinkFraming, Signing
    from ..transports.base import Transport
    from ..transports.mavlink import MavlinkSerialTransport, MavlinkUdpTransport

    sysid = spec.sysid if spec.sysid is not None else robot_id
    if not 1 <= sysid <= 255:
        if not listen_only:
            spec.check_sender(robot_id)
        sysid = 255  # a listener sends nothing; its sysid only decides which targeted TUNNELs are ours
    signing = None if spec.key is None else Signing(read_key(spec.key), spec.link_id)
    framing = MavlinkFraming(sysid, spec.compid, target=spec.target, signing=signing)
    heartbeat = None if listen_only else framing.heartbeat
    stamp = None if signing is None else framing.in_order  # signed frames leave in timestamp order
    transport: Transport[bytes]
    if spec.medium == "serial":
        transport = MavlinkSerialTransport(spec.where, spec.baud, heartbeat=heartbeat, air_rate=spec.air_rate,
                                           stamp=stamp, name=name)
    else:
        host, _, port = spec.where.rpartition(":")
        transport = MavlinkUdpTransport(spec.medium, (host.strip("[]"), int(port)), heartbeat=heartbeat,
                                        air_rate=spec.air_rate, stamp=stamp, name=name)
    if signing is None:
        log.warning("%s: WARNING: this MAVLink link is not signed (no key=): anyone on the radio or network can "
                    "read and write the swarm (give key=FILE, see docs/how-to/mavlink.md)", name)
    return Link(name, transport, framing)
