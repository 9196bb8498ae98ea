"""The compiled data path for a Node: its engine, guard, parts, outlets and delivery in C (vstig_hw._vstig).

A Node that relays (ENGINE or RAW) builds its parts here when this install has the
compiled path and `VSTIG_PURE` does not turn it off (`vstig_hw.native`). Each part
is the twin of the Python class it stands in for and has its interface, so the
Node's own Python (listeners, the API, ticks, stops) works on either:

* `Engine` for `Stigmergy`, `Seat` and `Relay` for the parts, `Outlet` (with a
  `Window`) for the outlets; the fair share's lines stay Python (`fairshare`),
  touched only while a backlog lasts, and so does each link's `LinkWriter`;
* `JumpGuard` for a guard of max_jump and learn only (the default); any other
  guard stays the Python one, which the compiled delivery asks per unit;
* `Receiver` for each link whose framing is cobs8, epuck4, kilobot, CAN, XBee
  (API mode 1 or 2, our 8-byte messages) or MAVLink (TUNNELs, the signature and
  replay checks with the replay table): its decoding lives there for the Node's
  life, whichever side delivers a batch;
* `Path`, the delivery (`delivery.Delivery.deliver`): one call per read. Links on a serial port
  or a SocketCAN bus are read by it (`pump`) and their writes go straight to the
  device while its writer is idle. An XBee link is read as its transport reads it:
  its module's bytes cut into frames (libvstig's), the module's own reports handed
  to the transport, one unit a frame. A mavlink UDP link's socket is read by it too
  (recvmmsg: each datagram's source into the link's peers, a compiled `UdpPeers`, a
  datagram that is not one frame cut as the transport cuts it), the transport's
  HEARTBEAT sent when its `beat` says, on the delivery's timer; while its writer is
  idle its outlet sends the TUNNELs to the socket itself (to the router, or to each
  live peer; a signed link's under its write lock, so frames leave in the order made)
  unless the link is paced (`air_rate=`): that, and a mavlink serial radio, go
  through the transport's Python (its token bucket).
  A CAN link on any other python-can interface (slcan, PCAN, Kvaser, Vector,
  virtual) is read by it through the bus's own recv, and while its writer is idle
  its outlet sends by the bus's own send(unit, 0.0) where that cannot block
  (`CanTransport.sends_at_once`): python-can's calls, no Python of ours between;
* with the swarm key, `Engine(swarm_key=)` for `SignedEngine` (tags.c): cobs8,
  CAN FD and XBee records are decoded by the Receiver and checked by the link's policy in
  the delivery, and an outlet that sends tags has its Encoder put each entry's
  record in (`send_tags`) and writes as an untagged one does (straight to a serial
  port, a SocketCAN socket or a python-can bus while its writer is idle). A link that checks
  tags the C does not send (MAVLink's tagged TUNNELs) keeps the whole Node in Python
  (`checks_tags_for`).

Everything else (zenoh, dialects, XbeeMav's packets, the overhead controller,
blabbermouth...) takes the Python path through the same parts. What decides which links the
compiled path reads and writes is here, in one place: `receiver_for`,
`encoder_for`, `reads_for`, `port_for`, `checks_tags_for`, `sends_tags`.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from ..auth import SwarmKeys, Tagged
from ..engine import ConflictResolver, Stigmergy
from ..framing.cobs8 import Cobs8Framing
from ..framing.epuck4 import Epuck4Framing
from ..framing.kilobot import KilobotFraming
from ..framing.mavlink import MavlinkFraming
from ..framing.xbee import XBeeApi2Framing, XBeeFraming
from ..links.link import Heard, Link
from ..native import native
from ..tagged import AuthPolicy
from ..transports.base import CompiledHandle
from ..transports.mavlink import MavlinkUdpTransport
from ..transports.serial import SerialTransport
from ..transports.xbee import XBeeTransport
from .delivery_state import DeliveryState
from .fairshare import FairFifo, FairQueue
from .guard import Guard
from .outlet import RAW_QUEUE_LIMIT, Outlet
from .parts import ChangeListener, RawRelay, Seat
from .writer import TX_QUEUE_LIMIT, LinkWriter

if TYPE_CHECKING:
    from .._vstig import Encoder, Path, Receiver
    from .._vstig import Engine as CompiledEngine
    from .._vstig import Outlet as _NativeOutlet
else:
    _NativeOutlet = object if native is None else native.Outlet

__all__ = ["Compiled", "compiled_for"]

MAX_EXPIRY_TICKS = 254  # epuck4 partials the compiled receiver can age (libvstig counts ticks in a byte)
MAX_LEARN = 2_097_151.0  # seconds of `learn` the compiled guard can count (2^31 of its 1/1024 s units)
# How the compiled delivery reads a link (path.h's VX_READ_*; tests/native compares them)
READS_PYTHON, READS_SERIAL, READS_SOCKETCAN, READS_XBEE, READS_UDP, READS_PYTHONCAN = 0, 1, 2, 3, 4, 5


def _is(obj: object, module: str, name: str) -> bool:
    """Whether `obj` is exactly `module`'s class `name`; False when that module was never imported (then nothing
    can be one of its objects): a serial gateway does not load python-can for this."""
    loaded = sys.modules.get(module)
    return loaded is not None and type(obj) is getattr(loaded, name)


def framing_of(link: Link[Any]) -> str | None:
    """The compiled framing that decodes and encodes exactly as the link's does (cobs8, epuck4, kilobot, can, xbee,
    mavlink), or None: the link's framing stays Python (zenoh, dialects, XbeeMav's packets, the overhead
    controller...)."""
    framing: Any = link.framing
    kind = type(framing)
    if kind is Cobs8Framing or kind is KilobotFraming:
        return str(framing.name)
    if kind is XBeeFraming or kind is XBeeApi2Framing:
        return "xbee"
    if kind is MavlinkFraming:
        return "mavlink"
    if kind is Epuck4Framing and framing.reassembler.expiry_ticks <= MAX_EXPIRY_TICKS:
        return "epuck4"
    if _is(framing, "vstig_hw.framing.can", "CanFraming"):
        return "can"
    return None


def receiver_for(link: Link[Any]) -> Receiver | None:
    """The link's framing as a compiled Receiver counting into the framing's own drops, or None (Python's)."""
    assert native is not None
    framing: Any = link.framing
    kind = framing_of(link)
    receiver: Receiver | None = None
    if kind == "cobs8":
        receiver = native.Receiver("cobs8", framing.drops)
    elif kind == "epuck4":
        receiver = native.Receiver("epuck4", framing.drops, expiry_ticks=framing.reassembler.expiry_ticks)
    elif kind == "kilobot":
        receiver = native.Receiver("kilobot", framing.drops, kilobot_type=framing.msg_type)
    elif kind == "can":
        scheme = framing.scheme
        receiver = native.Receiver("can", framing.drops, extended=scheme.extended, base=scheme.base,
                                   stigmergy=scheme.stigmergy)
    elif kind == "xbee":  # its ticks are the framing's too: they set which frame asks the module for a report
        receiver = native.Receiver("xbee", framing.drops, escaped=framing.escaped, on_tick=framing.tick)
    elif kind == "mavlink":  # the replay table is the Receiver's from now on
        receiver = native.Receiver("mavlink", framing.drops, sysid=framing.sysid, compid=framing.compid,
                                   key=None if framing.signing is None else framing.signing.key)
    return receiver


def encoder_for(link: Link[Any]) -> Encoder | None:
    """The link's framing as a compiled Encoder (the same units its framing makes), or None. An XBee framing sends
    with the Encoder's frame ids and NP from then on, so that either side's frames go on the same count."""
    assert native is not None
    framing: Any = link.framing
    kind = framing_of(link)
    encoder: Encoder | None = None
    if kind in ("cobs8", "epuck4"):
        encoder = native.Encoder(kind)
    elif kind == "kilobot":
        encoder = native.Encoder("kilobot", kilobot_type=framing.msg_type)
    elif kind == "can":
        import can

        scheme = framing.scheme
        encoder = native.Encoder("can", extended=scheme.extended, base=scheme.base, stigmergy=scheme.stigmergy,
                                 sender=framing.sender, fd=framing.fd, brs=framing.bitrate_switch,
                                 frame_type=can.Message)
    elif kind == "xbee":
        encoder = native.Encoder("xbee", escaped=framing.escaped, dest=framing.dest)
        framing.share_sending(encoder)
    elif kind == "mavlink":  # the framing's HEARTBEATs then go out through it: one sequence, one signing clock
        signing = framing.signing
        encoder = native.Encoder("mavlink", sysid=framing.sysid, compid=framing.compid, target=framing.target,
                                 key=None if signing is None else signing.key,
                                 link_id=0 if signing is None else signing.link_id)
        framing.share_sending(encoder)
    return encoder


def reads_for(link: Link[Any]) -> int:
    """How the compiled delivery reads the link: READS_SERIAL a serial port's fd, READS_SOCKETCAN a SocketCAN
    socket, READS_XBEE an XBee module's serial fd (cut into frames as its transport cuts them), READS_UDP a MAVLink
    UDP socket, READS_PYTHONCAN any other python-can bus (its own recv, called by the delivery), READS_PYTHON through
    its transport's own read."""
    transport = link.transport
    if type(transport) is MavlinkUdpTransport:
        return READS_UDP  # while the socket is open; pump hands an outage back
    if type(transport) is SerialTransport:
        return READS_SERIAL  # while the port has an fd (a device or a pty); pump hands socket:// and outages back
    if type(transport) is XBeeTransport:
        return READS_XBEE  # likewise, and while the transport holds nothing it read at open
    if _is(transport, "vstig_hw.transports.can", "CanTransport"):  # pump hands outages and python-can's errors back
        return READS_SOCKETCAN if getattr(transport, "interface", "") == "socketcan" else READS_PYTHONCAN
    return READS_PYTHON


def port_for(link: Link[Any]) -> str:
    """Where the compiled outlet writes while the link's writer is idle: the device itself, or the writer."""
    reads, transport = reads_for(link), link.transport
    if reads == READS_PYTHONCAN:  # python-can's own send(unit, 0.0), called by the outlet (the handle's bus)
        can_transport: Any = transport  # a CanTransport (its module imports python-can: not imported here)
        return "pythoncan" if can_transport.sends_at_once else "python"
    if type(transport) is MavlinkUdpTransport and not transport.writes_as_made:
        return "python"  # paced to an air rate: the transport's own write keeps the bucket
    return ("python", "serial", "socketcan", "serial", "udp")[reads]  # an XBee module's writes: a serial port's


def compile_peers(handle: CompiledHandle[Any]) -> None:
    """A udpin link read in C keeps its peers in C (the delivery notes each datagram's source without Python):
    the transport's UdpPeers becomes its compiled twin (a Node builds it before its links open; peers a link heard
    before then are kept, heard now)."""
    assert native is not None
    peers = handle.peers
    if peers is None or type(peers) is native.UdpPeers:
        return
    twin = native.UdpPeers(peers.most, peers.timeout)
    now = time.monotonic()
    for address in peers.live(now):
        twin.heard(address, now)
    handle.peers = twin


def jump_guard(guard: Guard | None) -> Guard | None:
    """A guard of max_jump and learn alone as a compiled JumpGuard; any other guard (or none) as it is."""
    if guard is None or native is None:
        return guard
    only_jump = (guard.max_jump is not None and guard.rate is None and guard.source_rate is None
                 and guard.flap is None and not guard.policies
                 and (guard.learn is None or (math.isfinite(guard.learn) and guard.learn < MAX_LEARN)))
    if not only_jump:
        return guard
    compiled: Guard = native.JumpGuard(guard.max_jump, guard.learn)
    return compiled


class CompiledOutlet(_NativeOutlet):
    """The C Outlet with the calls a stop and a confirmed write make, the pure Outlet's own: neither is on the
    data path, and what they use (`handed`, the window, the writer, the length) is the C Outlet's."""

    send_now = Outlet.send_now
    close = Outlet.close


class Compiled:
    """Builds a Node's parts in C (see the module's docstring); one per Node."""

    def __init__(self) -> None:
        assert native is not None
        self.native = native
        self._sending_tags: list[tuple[Encoder, Link[Any]]] = []  # the outlets' encoders that send records

    def outlet(self, link: Link[Any], budget: int | None, period: float, *, keep_all: bool = False,
               on_room: Callable[[], None] | None = None) -> Outlet:
        writer = LinkWriter(link, TX_QUEUE_LIMIT, on_room=on_room)
        queue = FairFifo(RAW_QUEUE_LIMIT) if keep_all else FairQueue()
        encoder = encoder_for(link)
        port = port_for(link) if encoder is not None else "python"
        if encoder is not None and sends_tags(link):  # its records from the engine (`signed_engine`)
            self._sending_tags.append((encoder, link))
        outlet: Outlet = CompiledOutlet(link, writer, self.native.Window(budget, period), queue,
                                        keep_all=keep_all, encoder=encoder, port=port)
        return outlet

    def engine(self, robot_id: int, onconflict: ConflictResolver | None) -> Stigmergy:
        engine: Stigmergy = self.native.Engine(robot_id, onconflict)
        return engine

    def signed_engine(self, robot_id: int, onconflict: ConflictResolver | None, keys: SwarmKeys) -> CompiledEngine:
        """The engine of a Node with the swarm key: SignedEngine's twin (tags.c), writers' keys derived in C; the
        outlets built before it that send tags take each message's record from it."""
        engine: CompiledEngine = self.native.Engine(robot_id, onconflict, swarm_key=keys.master,
                                                    stigmergy=keys.stigmergy, policies=tuple(AuthPolicy),
                                                    record=Tagged)
        for encoder, link in self._sending_tags:
            encoder.send_tags(engine, link.auth is AuthPolicy.REQUIRE, link.counters)
        return engine

    def seat(self, engine: Stigmergy, links: list[Link[Any]], outlets: list[Outlet], guard: Guard | None,
             on_change: Sequence[ChangeListener], intake: int | None, period: float) -> Seat:
        seat: Seat = self.native.Seat(engine, links, outlets, guard, on_change, intake, period)
        return seat

    def relay(self, outlets: list[Outlet], guard: Guard | None) -> RawRelay:
        relay: RawRelay = self.native.Relay(outlets, guard)
        return relay

    def path(self, state: DeliveryState, lock: object, deliver: Callable[[int, float, list[Any]], None],
             links: list[Link[Any]], receivers: list[Receiver | None], part: Seat | RawRelay | None,
             guard: Guard | None, outlets: list[Outlet], listeners: list[Sequence[Any]],
             told: list[tuple[Callable[..., None], ...]], delivered: list[Callable[[float], None]]) -> Path:
        """The delivery; `state`: what it shares with the Node's loop; `listeners`: the Node's listeners that want
        each unit or every `Heard`, one sequence per kind (while any has one, batches take the Python delivery);
        `told`: the `messages` and `refused` listeners it tells itself; `delivered`: those told of every batch
        handled (its read time). The lists are the Node's own, kept up to date in place: the delivery looks at them
        per read."""
        reads = [reads_for(link) if receiver is not None else READS_PYTHON
                 for link, receiver in zip(links, receivers, strict=True)]
        for link, how in zip(links, reads, strict=True):
            handle = link.transport.compiled_handle()
            if how == READS_UDP and handle is not None:
                compile_peers(handle)
        can = sys.modules.get("can")  # loaded if a link is CAN: the frames the delivery hands Python are its Messages
        path: Path = self.native.Path(state, lock, deliver, links, receivers, reads, part, guard, outlets,
                                      listeners=listeners, told=told, heard=Heard, delivered=delivered,
                                      can_message=None if can is None else can.Message)
        return path


def compiled_for(relays: bool, links: Sequence[Link[Any]]) -> Compiled | None:
    """The builder for a Node that relays (ENGINE or RAW) over at least one link the compiled path decodes, when
    this install has it; else None (the Node is pure Python: nothing it reads would be decoded in C). A Node with
    the swarm key also needs every link to pass `checks_tags_for`."""
    if not relays or native is None or not any(framing_of(link) is not None for link in links):
        return None
    return Compiled()


def checks_tags_for(link: Link[Any]) -> bool:
    """Whether the compiled path can check and send the link's tags as its framing does: a link with auth off, one
    whose framing stays Python (zenoh, ROS 2...: the Python delivery checks it, the compiled engine keeps the
    proofs), one whose framing carries no tags (nothing to check), or cobs8, CAN and XBee, whose records the
    compiled Receiver decodes and Encoder sends (MAVLink's tagged TUNNELs are Python's only: a Node with such a link
    that checks tags runs in Python)."""
    kind = framing_of(link)
    return (link.auth is AuthPolicy.OFF or kind is None or kind in ("cobs8", "can", "xbee")
            or not link.framing.carries_tags)


def sends_tags(link: Link[Any]) -> bool:
    """Whether the link's outlet sends records (a link that checks tags and has room for them): its Encoder then
    puts each message's record from the engine in (`Encoder.send_tags`), written as an untagged outlet's units are."""
    return link.auth is not AuthPolicy.OFF and bool(link.framing.carries_tags)
