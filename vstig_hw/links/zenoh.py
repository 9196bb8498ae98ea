"""Zenoh links (`zenoh:` specs): an embedded Zenoh session + the vstig Zenoh framing (firmware_spec/SPEC.md, "Zenoh").

Closed by default. Zenoh's own defaults listen on every interface and scout the
LAN by multicast; a gateway built here listens on a free loopback port and does
no multicast scouting unless the spec (`listen=`, `scout=1`) or the Zenoh config
file says otherwise. The port is picked when the link is built and bound when its
session opens; should another program take it in between, the session opens on a
fresh one (Zenoh's Python API cannot report a port it picked itself from port 0,
short of opening its admin space to every peer). A config file (read under the file rules: zenoh_files) passes
through: only the keys the spec names override it, and our closed defaults and bounds fill only what it leaves
unset; where it loosens a bound (`bounds`: what one peer can make the gateway hold), one line says so.

Opening a link that lets unauthenticated peers in from beyond this PC logs one
warning line (`exposure`): a listener not reachable from this PC alone, unless
Zenoh makes every peer authenticate or it is a TLS/QUIC listener with mutual
TLS, or multicast scouting without such authentication. The loopback default is
open to every user of this PC (docs/how-to/many-pcs.md).

The zenoh library is imported when a link is built, not when a spec is parsed.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import re
import socket
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from ..framing.zenoh import MAX_SAMPLE, MAX_STIGMERGY, ZenohFraming, ZenohKeySpace, check_swarm
from ..inputs import InputFileError
from ..tagged import AuthPolicy
from ..transports.base import TransportError, one_line
from ..wire import MESSAGE_SIZE
from .grammar import bad, flag, integer, safe_name, split_query
from .link import Link, LinkSpec
from .zenoh_files import NAMED_FILES, ConfigFile, check_listen_path, read_config, read_named, users_in

if TYPE_CHECKING:
    import zenoh

__all__ = ["EXAMPLES", "GRAMMAR", "NOTES", "BuiltConfig", "ZenohSpec", "bounds", "build_config", "exposure",
           "parse_zenoh", "zenoh_config", "zenoh_link_from_spec"]

GRAMMAR = (
    "zenoh:<swarm>[?mode=peer|client&connect=<endpoint>[,...]&listen=<endpoint>[,...]&config=<zenoh json5 file>"
    "&stigmergy=N&scout=0|1&max_sample=<bytes>&echo=1]",
)
EXAMPLES = {
    "zenoh": ("zenoh:lab", "zenoh:lab?listen=tcp/0.0.0.0:7447&config=lab.json5",
              "zenoh:lab?connect=tcp/10.0.0.5:7447",
              "zenoh:lab?mode=client&connect=tls/router.lab:7447&config=lab.json5",
              "zenoh:lab?scout=1&stigmergy=2"),
}
# For `vstig links`: what the options mean beyond the grammar.
NOTES = {
    "zenoh": "zenoh: gateways on many PCs as one swarm (key vstig/<swarm>/<stigmergy>/<gateway id>). Closed by "
             "default: listens on a free loopback port (printed once open), no multicast scouting; listen=, connect= "
             "or scout=1 open it, config= passes a Zenoh JSON5 config file (TLS, user/password, routers) through. A "
             f"sample above max_sample= bytes (default {MAX_SAMPLE}) is refused unread and counted (rx_oversize); "
             "Zenoh holds none above max_sample + 64 KiB, and shares no memory with local peers. One "
             "broadcast domain: a PUT heard on zenoh is not published back onto it; echo=1 does (peers that do not "
             "all reach each other, with no router).",
}
_EXAMPLE = EXAMPLES["zenoh"][0]
_MAX_SAMPLE_CEILING = 64 * 1024 * 1024  # max_sample= above this would let one peer take the PC's memory


@dataclass(frozen=True, slots=True)
class ZenohSpec(LinkSpec):
    swarm: str
    mode: str | None = None  # None: the config file's, else peer
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config: str | None = None
    stigmergy: int = 0
    scout: bool | None = None  # None: the config file's, else off
    block: bool = False  # Zenoh congestion control BLOCK instead of DROP: set by commands that must not lose a sample
    peer_wait: float | None = None  # seconds opening may wait for a peer it connects to (None: 3); one-shot commands
    max_sample: int = MAX_SAMPLE  # payload bytes: a bigger sample is refused before it is decoded
    echo: bool = False  # True: a PUT heard on zenoh is published back onto it (Link.one_domain off)
    auth: AuthPolicy = AuthPolicy.OFF  # auth=: what the link does with untagged messages (SPEC.md 10.6)
    capture_medium = "zenoh"  # our zenoh line capture: samples keep their keys

    @property
    def kind(self) -> str:
        return "zenoh"

    @property
    def name(self) -> str:
        return safe_name(f"zenoh-{self.swarm}")

    def build(self, name: str | None = None, *, robot_id: int = 0, listen_only: bool = False) -> Link[Any]:
        """The Link (not yet open); `robot_id` names this gateway in the key space (vstig/<swarm>/<stig>/<id>)."""
        from ..extras import require

        require("zenoh", "a zenoh: link")  # before any link of the command opens
        return zenoh_link_from_spec(self, name or self.name, robot_id=robot_id, listen_only=listen_only)

    def for_table(self, table: int, listening: tuple[str, ...] = ()) -> LinkSpec:
        """The same swarm in `table`'s key space, in a session that cannot bind this one's endpoints again: it
        listens on none and connects where this one connects and to this one's own endpoints (`listening`)."""
        return replace(self, stigmergy=table, listen=(), connect=tuple(dict.fromkeys((*self.connect, *listening))))

    def lossless(self, opening: float | None = None) -> LinkSpec:
        """Congestion control BLOCK, not DROP; `opening` bounds the wait for a peer it connects to (else 3 s)."""
        return replace(self, block=True, peer_wait=self.peer_wait if opening is None else opening)

    @property
    def files_read(self) -> tuple[str, ...]:
        return (self.config,) if self.config else ()


_ZENOH_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream", "unixpipe", "vsock", "serial")


def _spec_endpoints(spec: str, key: str, text: str) -> tuple[str, ...]:
    endpoints = tuple(text.split(","))
    for endpoint in endpoints:
        protocol, sep, address = endpoint.partition("/")
        if not sep or not address or any(ch.isspace() for ch in endpoint):
            raise bad(spec, f"{key}={endpoint!r} is not a Zenoh endpoint <protocol>/<address> "
                            "(e.g. tcp/10.0.0.5:7447)", _EXAMPLE)
        if protocol not in _ZENOH_PROTOCOLS:
            raise bad(spec, f"{key}={endpoint!r}: unknown protocol {protocol!r} "
                            f"(known: {', '.join(_ZENOH_PROTOCOLS)})", _EXAMPLE)
    return endpoints


def parse_zenoh(spec: str, body: str) -> ZenohSpec:
    """`body` is the spec after `zenoh:`; the key space (framing.zenoh) judges the swarm name."""
    swarm, params = split_query(spec, body, _EXAMPLE, ("mode", "connect", "listen", "config", "stigmergy", "scout",
                                                                "max_sample", "echo"))
    try:
        check_swarm(swarm)
    except ValueError as error:
        raise bad(spec, str(error), _EXAMPLE) from None
    mode = params.get("mode")
    if mode is not None and mode not in ("peer", "client"):
        raise bad(spec, f"mode={mode!r} must be peer or client", _EXAMPLE)
    connect = _spec_endpoints(spec, "connect", params["connect"]) if "connect" in params else ()
    listen = _spec_endpoints(spec, "listen", params["listen"]) if "listen" in params else ()
    if mode == "client" and listen:
        raise bad(spec, "a client does not listen: drop listen= or use mode=peer", _EXAMPLE)
    if mode == "client" and not connect and "config" not in params:
        raise bad(spec, "a client needs connect=<router endpoint> (or a config= file naming one)", _EXAMPLE)
    config = params.get("config")
    if config is not None and any(ch in config for ch in "\0\n\r"):
        raise bad(spec, "the config path contains a control character", _EXAMPLE)
    return ZenohSpec(
        swarm=swarm,
        mode=mode,
        connect=connect,
        listen=listen,
        config=config,
        stigmergy=integer(spec, _EXAMPLE, "stigmergy", params["stigmergy"], 0, MAX_STIGMERGY)
        if "stigmergy" in params else 0,
        scout=flag(spec, _EXAMPLE, "scout", params["scout"]) if "scout" in params else None,
        max_sample=integer(spec, _EXAMPLE, "max_sample", params["max_sample"], MESSAGE_SIZE, _MAX_SAMPLE_CEILING)
        if "max_sample" in params else MAX_SAMPLE,
        echo=flag(spec, _EXAMPLE, "echo", params["echo"]) if "echo" in params else False,
    )


log = logging.getLogger(__name__)

_LOCAL_PROTOCOLS = ("unixsock-stream", "unixpipe")  # reached through this PC's file system only
_TLS_PROTOCOLS = ("tls", "quic")  # the links mutual TLS authenticates
_VSOCK_LOCAL = ("VMADDR_CID_LOCAL", "1")  # vsock's own-machine address; any other CID is reached from VMs
HEADROOM = 64 * 1024  # beside a sample's payload: its key, timestamp, encoding, attachment


def bounds(max_sample: int) -> dict[str, Any]:
    """The Zenoh settings that bound what peers can make a gateway hold, for samples of `max_sample` payload
    bytes at most (DECISIONS.md, "What a Zenoh peer can make a gateway hold")."""
    return {
        # Zenoh reassembles a fragmented sample up to this size (its default: 1 GiB), then drops it: one 900 MiB
        # sample took a gateway to 958 MB, which stayed after the peer left; bounded, it stays near 34 MB.
        "transport/link/rx/max_message_size": max_sample + HEADROOM,
        # A local peer's shared-memory pool (16 MiB) is mapped by whoever reads from it, and stayed mapped after
        # the peer left: +16-20 MB per peer that flooded and left. Off, local peers go through loopback.
        "transport/shared_memory/enabled": False,
    }


def _free_loopback_port() -> int:
    """A TCP port free on 127.0.0.1 now, so several gateways on one PC do not collide."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _json(config: zenoh.Config, key: str) -> Any:
    return json.loads(config.get_json(key))


def _loopback_listener(protocol: str) -> list[str]:
    return [f"{protocol}/127.0.0.1:{_free_loopback_port()}"]


@dataclass(frozen=True, slots=True)
class BuiltConfig:
    """A link's Zenoh config, and what building it found."""

    config: zenoh.Config
    ours: str | None  # the protocol of the loopback listener we chose for it (None if we chose none)
    overridden: tuple[str, ...]  # why the config file's own values loosen our bounds, one line each


def zenoh_config(spec: ZenohSpec) -> zenoh.Config:
    """The Zenoh configuration for `spec`: its file (if any), then the spec's keys, then our closed defaults."""
    return build_config(spec).config


def build_config(spec: ZenohSpec) -> BuiltConfig:
    """The one place a link's Zenoh config is made: the config file read under the file rules (zenoh_files), the
    spec's keys over it, our closed defaults and bounds where the file leaves them unset, and every file it names
    and unix socket it listens on checked before Zenoh opens any. TransportError names what is wrong."""
    import zenoh

    file = None
    if spec.config:
        try:
            file = read_config(spec.config)
            config = zenoh.Config.from_json5(file.text)
        except InputFileError as error:
            raise TransportError(f"cannot read the Zenoh config file: {error}") from None
        except zenoh.ZError as error:
            raise TransportError(f"cannot read the Zenoh config file {_zenoh_error_at(file, error)}") from None
    else:
        config = zenoh.Config()
    zenoh_default = zenoh.Config()
    if spec.mode is not None:
        config.insert_json5("mode", json.dumps(spec.mode))
    elif not spec.config:
        config.insert_json5("mode", '"peer"')
    if spec.connect:
        config.insert_json5("connect/endpoints", json.dumps(list(spec.connect)))
    ours = None
    if spec.listen:
        config.insert_json5("listen/endpoints", json.dumps(list(spec.listen)))
    elif _json(config, "listen/endpoints") == _json(zenoh_default, "listen/endpoints"):
        ours = _loopback_protocol(config)
        config.insert_json5("listen/endpoints", json.dumps(_loopback_listener(ours) if ours else []))
    if spec.scout is not None:
        config.insert_json5("scouting/multicast/enabled", json.dumps(spec.scout))
    elif _json(config, "scouting/multicast/enabled") is None:
        config.insert_json5("scouting/multicast/enabled", "false")
    if _json(config, "timestamping/enabled") is None:  # stamped samples name their session: --source-rate
        config.insert_json5("timestamping/enabled", "true")
    overridden = []
    for key, value in bounds(spec.max_sample).items():
        if file is None or key not in file.keys:
            config.insert_json5(key, json.dumps(value))
        elif _json(config, key) > value:  # a larger size, or shared memory on (True > False): looser than ours
            overridden.append(f"{file.where(key)} sets {key} to {config.get_json(key)} (vstig's default: "
                              f"{json.dumps(value)}): {_LOOSENED[key]}")
    _check_files(config, file)
    return BuiltConfig(config, ours, tuple(overridden))


_LOOSENED = {
    "transport/link/rx/max_message_size": "one peer's sample can take that much of this PC's memory",
    "transport/shared_memory/enabled": "each local peer's shared memory may stay mapped here after it leaves",
}


def _zenoh_error_at(file: ConfigFile | None, error: Exception) -> str:
    """`path:line: why` for Zenoh's error about a config file (its parser's ` --> line:column`, or the line of
    a field it names)."""
    assert file is not None
    text = str(error)
    position = re.search(r"-->\s*(\d+):\d+", text)
    reason = text.splitlines()[-1].lstrip(" =") if position else one_line(error).split(" at /", 1)[0]
    line = f":{position.group(1)}" if position else file.line_of_field(text)
    return f"{file.path}{line}: {reason}"


def _check_files(config: zenoh.Config, file: ConfigFile | None) -> None:
    """Every file the config names, read as vstig reads named files, and every unix socket path it listens on,
    checked now: a device or FIFO there would hold or swamp Zenoh, a file there would be replaced."""
    for key, what in NAMED_FILES.items():
        path = _json(config, key)
        if isinstance(path, str):
            try:
                read_named(path, what)
            except InputFileError as error:
                where = file.where(key) if file is not None else "the Zenoh config"
                raise TransportError(f"{where}: {key}: {error}") from None
    for side in ("listen", "connect"):
        for endpoint in _endpoints(config, f"{side}/endpoints"):
            _, _, settings = endpoint.partition("#")
            for name, _, path in (item.partition("=") for item in settings.split(";")):
                if name.endswith("_file") and path:
                    try:
                        read_named(path, f"the {name} of {endpoint.split('#', 1)[0]}")
                    except InputFileError as error:
                        raise TransportError(f"{side}={endpoint}: {error}") from None
    for endpoint in _endpoints(config, "listen/endpoints"):
        protocol, _, address = endpoint.partition("/")
        if protocol == "unixsock-stream":
            try:
                check_listen_path(address.split("?", 1)[0].split("#", 1)[0])
            except InputFileError as error:
                raise TransportError(f"listen={endpoint}: {error}") from None


def _loopback_protocol(config: zenoh.Config) -> str | None:
    """The default loopback listener's protocol: tcp, or tls where the config allows only TLS; none for a client."""
    if _mode(config) == "client":
        return None
    allowed = _json(config, "transport/link/protocols")
    if not allowed or "tcp" in allowed:
        return "tcp"
    return "tls" if "tls" in allowed else None


def _mode(config: zenoh.Config) -> str:
    mode = _json(config, "mode")
    return mode if isinstance(mode, str) else "peer"


def _endpoints(config: zenoh.Config, key: str) -> list[str]:
    """A list of endpoints, or Zenoh's per-mode form {router: [...], peer: [...]} resolved for this mode."""
    value = _json(config, key)
    if isinstance(value, dict):
        value = value.get(_mode(config)) or []
    return [str(v) for v in value or []]


def _host(address: str) -> str:
    """The host of an endpoint's address (`host:port`, `[v6]:port`), its metadata and settings left off."""
    address = address.split("?", 1)[0].split("#", 1)[0]
    if address.startswith("["):
        return address[1:].split("]", 1)[0]
    return address.rsplit(":", 1)[0]


def _is_local(endpoint: str) -> bool:
    """Whether only this PC can reach `endpoint`: a loopback address written as one (127.0.0.0/8, ::1, an IPv4
    loopback mapped into IPv6), `localhost` itself, a unix socket or pipe, vsock's local CID. A name is judged by
    what it is, never resolved (`localhost.example` or `127.0.0.1.example` may resolve anywhere)."""
    protocol, _, address = endpoint.partition("/")
    if protocol in _LOCAL_PROTOCOLS:
        return True
    host = _host(address)
    if protocol == "vsock":
        return host in _VSOCK_LOCAL
    if host.lower() == "localhost":
        return True
    try:
        ip = ipaddress.ip_address(host.split("%", 1)[0])
    except ValueError:
        return False
    mapped = ip.ipv4_mapped if isinstance(ip, ipaddress.IPv6Address) else None
    return ip.is_loopback or (mapped is not None and mapped.is_loopback)


def _every_peer_authenticates(config: zenoh.Config) -> bool:
    """Whether Zenoh makes every session, on any link, authenticate (Zenoh 1.10, transport/auth): user/password
    once this gateway has credentials of its own or a dictionary with at least one user (an empty one turns it
    off), public keys once it has a key pair (Zenoh reads no known_keys_file: it is not a check)."""
    usrpwd = "transport/auth/usrpwd/"
    if _json(config, usrpwd + "user") is not None and _json(config, usrpwd + "password") is not None:
        return True
    dictionary = _json(config, usrpwd + "dictionary_file")
    if isinstance(dictionary, str) and users_in(dictionary):
        return True
    pubkey = "transport/auth/pubkey/"
    return any(_json(config, pubkey + f"public_key_{form}") is not None
               and _json(config, pubkey + f"private_key_{form}") is not None for form in ("pem", "file"))


def _mtls(config: zenoh.Config) -> bool:
    return bool(_json(config, "transport/link/tls/enable_mtls"))


def _client_certificate_needed(config: zenoh.Config, endpoint: str) -> bool:
    """Whether a peer reaching `endpoint` must show a certificate: mutual TLS covers TLS and QUIC links only."""
    return _mtls(config) and endpoint.partition("/")[0] in _TLS_PROTOCOLS


def exposure(config: zenoh.Config) -> str | None:
    """Why this configuration lets unauthenticated peers in from beyond this PC, or None if it does not."""
    if _every_peer_authenticates(config):
        return None
    reasons = []
    beyond = [e for e in _endpoints(config, "listen/endpoints")
              if not _is_local(e) and not _client_certificate_needed(config, e)]
    if beyond:
        reasons.append(f"listens on {', '.join(beyond)}")
    allowed = _json(config, "transport/link/protocols")
    tls_only = _mtls(config) and bool(allowed) and set(allowed) <= set(_TLS_PROTOCOLS)
    if _json(config, "scouting/multicast/enabled") is not False and not tls_only:
        reasons.append("scouts the LAN by multicast")
    return " and ".join(reasons) or None


def zenoh_link_from_spec(spec: ZenohSpec, name: str, *, robot_id: int = 0,
                         listen_only: bool = False) -> Link[Any]:
    """A Zenoh link (not yet open) publishing as gateway `robot_id` (0 when it never transmits)."""
    from ..transports.zenoh import ZenohTransport
    from ..transports.zenoh_clock import ZenohClock

    space = ZenohKeySpace(spec.swarm, spec.stigmergy)
    framing = ZenohFraming(space, 0 if listen_only else robot_id)
    built = build_config(spec)  # read once now, so a bad file or value fails before anything opens
    first, ours = built.config, built.ours
    connecting = _endpoints(first, "connect/endpoints")
    made = [first]

    def make_config() -> zenoh.Config:  # a reopened session listens where the last one did
        if made:
            return made.pop()
        config = zenoh_config(spec)
        config.insert_json5("listen/endpoints", json.dumps(list(transport.listening)))
        return config

    def fresh_listener() -> tuple[str, ...]:  # our loopback port was taken before the session bound it
        assert ours is not None
        made.clear()
        return tuple(_loopback_listener(ours))

    for why in built.overridden:
        log.warning("%s: %s", name, why)
    open_to = exposure(first)
    if open_to:
        log.warning("%s: WARNING: this gateway %s with no authentication: anyone on the network can read "
                    "and write the swarm (configure TLS and user/password with config=, see docs/how-to/many-pcs.md)",
                    name, open_to)
    reaches = "; ".join(filter(None, (
        f"connecting to {', '.join(connecting)}" if connecting else "",
        "scouting by multicast" if _json(first, "scouting/multicast/enabled") is not False else "")))
    transport = ZenohTransport(make_config, space.subscription, name=name, block=spec.block,
                               expects_peer=bool(connecting) or _mode(first) == "client", connecting=tuple(connecting),
                               listening=tuple(_endpoints(first, "listen/endpoints")), reaches=reaches,
                               rebind=fresh_listener if ours else None, peer_wait=spec.peer_wait,
                               max_sample=spec.max_sample, clock=ZenohClock(space.clock_prefix))
    # Every gateway of the swarm hears every sample: a PUT heard here is not published back here (unless echo=1:
    # peers that do not all reach each other, and no router, where a gateway's re-broadcast carries it a hop on).
    return Link(name, transport, framing, one_domain=not spec.echo)
