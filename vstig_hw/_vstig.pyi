"""Types of the compiled data path (vstig_hw/_cext, built by setup.py), and the one index of the twins.

firmware_spec/SPEC.md is normative. The Python is the reference implementation of it that the gateway runs; each
C file here is a twin held equal to its Python reference by tests/native (the same counters, frames and answers on
random traffic), and names it at its top ("Reference:"), as each reference names its twin ("C twin:"). The stub
says which class a type stands in for by naming it as its base (the compiled types do not really subclass it:
nothing checks them with isinstance). tests/native/test_native_twins_named.py checks this table both ways.

Twins (C file, its types, its Python references):

    engine.c   Engine             vstig_hw/engine.py
    tags.c     -                  vstig_hw/gateway/signing.py vstig_hw/tagged.py
    guard.c    JumpGuard          vstig_hw/gateway/guard.py
    framing.c  Receiver Encoder   vstig_hw/framing/cobs8.py vstig_hw/framing/epuck4.py vstig_hw/framing/kilobot.py
                                  vstig_hw/framing/can.py vstig_hw/framing/xbee.py vstig_hw/framing/mavlink.py
    mavlink.c  -                  vstig_hw/framing/mavlink.py
    window.c   Window             vstig_hw/gateway/outlet.py
    outlet.c   Outlet             vstig_hw/gateway/outlet.py vstig_hw/transports/serial.py vstig_hw/transports/can.py
                                  vstig_hw/transports/mavlink.py
    parts.c    Seat Relay         vstig_hw/gateway/parts.py
    path.c     Path               vstig_hw/gateway/delivery.py vstig_hw/gateway/outbound.py
                                  vstig_hw/gateway/delivery_state.py
                                  vstig_hw/transports/serial.py vstig_hw/transports/can.py vstig_hw/transports/xbee.py
                                  vstig_hw/transports/mavlink.py
    peers.c    UdpPeers           vstig_hw/transports/mavlink.py
    roster.c   RosterTally        vstig_hw/gateway/roster.py
    pending.c  PendingCounts      vstig_hw/counters.py
    module.c   -                  vstig_hw/native.py

Constants both sides use are defined once on each side and compared by tests/native/test_native_twins_named.py
(it parses the C #defines); a C #define it does not know fails it until it is classified.
"""
from collections.abc import Callable, Sequence
from typing import Any

from .auth import Tagged
from .counters import Counters
from .engine import Entry, Outcome, Stigmergy
from .gateway.delivery_state import DeliveryState
from .gateway.fairshare import FairFifo, FairQueue
from .gateway.guard import Guard
from .gateway.outlet import Outlet as _Outlet
from .gateway.outlet import SendWindow
from .gateway.parts import RawRelay
from .gateway.parts import Seat as _Seat
from .gateway.writer import LinkWriter
from .links.link import Heard, Link
from .tagged import AuthPolicy
from .wire import Message

KEYS: int
# The attribute names the C uses on each declared Python type ("module:qualname"), from module.c's one table.
DECLARED: dict[str, tuple[str, ...]]

def setup(message: type[Message], entry: type[Entry], outcomes: tuple[Outcome, ...],
          rules: tuple[Any, Any, Any]) -> None: ...

class Engine(Stigmergy):
    # Given swarm_key it is SignedEngine's twin (tags.c): `policy`, `records` and `record_of` are then its
    policy: AuthPolicy
    records: dict[Message, Tagged] | None
    @property
    def replays(self) -> int: ...
    def __init__(self, robot_id: int, onconflict: Any = None, onconflictlost: Any = None, *,
                 swarm_key: bytes | None = None, stigmergy: int = 0, policies: tuple[AuthPolicy, ...] = (),
                 record: type[Tagged] | None = None) -> None: ...
    def record_of(self, msg: Message) -> Tagged | None: ...

class JumpGuard(Guard):
    def __init__(self, max_jump: int, learn: float | None = None) -> None: ...
    def view(self, key: int) -> tuple[int, int, int] | None: ...

class Receiver:
    sender: int | None  # the last unit's sender: XBee's 64-bit source, MAVLink's sysid << 8 | compid
    def __init__(self, framing: str, drops: Counters, *, expiry_ticks: int = 3, kilobot_type: int = 0x56,
                 extended: bool = False, base: int | None = None, stigmergy: int = 0, escaped: bool = False,
                 on_tick: Callable[[], None] | None = None, sysid: int = 1, compid: int = 191,
                 key: bytes | None = None) -> None: ...
    def feed(self, unit: Any) -> list[Message]: ...
    # a link of a Node with the swarm key (cobs8 and CAN FD units carry records: SPEC.md 10.5)
    def check_tags(self, auth: int, refuse: Callable[[Message, str, float, int | None, Any], None], /) -> None: ...
    def feed_tagged(self, unit: Any) -> list[tuple[Message, tuple[int, bytes] | None]]: ...
    def tick(self) -> None: ...
    def reset(self) -> None: ...

class Encoder:
    frame_id: int  # XBee: the fields an XBeeFraming sends with once it shares them (framing.xbee.Sending)
    report: int
    per_frame: int
    records_per_frame: int
    seq: int  # MAVLink: the next frame's sequence, and the last signing timestamp sent (the framing shares them)
    timestamp: int
    written: int  # MAVLink: the newest signing timestamp the link wrote (the framing's in_order, the outlet's sends)
    def __init__(self, framing: str, *, kilobot_type: int = 0x56, extended: bool = False, base: int | None = None,
                 stigmergy: int = 0, sender: int = 0, fd: bool = False, brs: bool = True,
                 frame_type: Any = None, escaped: bool = False, dest: int = 0xFFFF, sysid: int = 1,
                 compid: int = 191, target: int = 0, key: bytes | None = None, link_id: int = 0) -> None: ...
    def encode_batch(self, messages: Sequence[Message]) -> list[Any]: ...
    def send_tags(self, engine: Engine, require: bool, counters: Counters, /) -> None: ...
    def heartbeat(self) -> bytes: ...

class Window(SendWindow): ...

class Outlet(_Outlet):
    def __init__(self, link: Link[Any], writer: LinkWriter, window: Window, queue: FairQueue | FairFifo, *,
                 keep_all: bool = False, encoder: Encoder | None = None, port: str = "python") -> None: ...

class Seat(_Seat): ...

class Relay(RawRelay): ...

class Path:
    fast: bool
    stopping: bool
    def __init__(self, state: DeliveryState, lock: object, deliver: Callable[[int, float, list[Any]], None],
                 links: list[Link[Any]], receivers: list[Receiver | None], reads: list[int],
                 part: _Seat | RawRelay | None, guard: Guard | None, outlets: list[_Outlet], *,
                 listeners: list[Sequence[Any]], told: list[tuple[Callable[..., None], ...]], heard: type,
                 delivered: Sequence[Callable[[float], None]],
                 can_message: object = None) -> None: ...
    def deliver(self, index: int, t: float, units: list[Any], now: float | None = None) -> bool: ...
    def pump(self, index: int, timeout: float) -> int | None: ...
    def pumps(self, index: int) -> bool: ...
    def serve(self, index: int, timeout: float, turn: Callable[[], None]) -> None: ...

class UdpPeers:  # transports.mavlink.UdpPeers: a udpin link's peers
    most: int
    timeout: float
    def __init__(self, most: int = 8, timeout: float = 10.0) -> None: ...
    def __len__(self) -> int: ...
    def heard(self, address: tuple[Any, ...], now: float, /) -> None: ...
    def live(self, now: float, /) -> list[tuple[Any, ...]]: ...

class RosterTally:  # a Tally (gateway/roster.py)
    def __init__(self, max_robots: int, quiet_after: float, gone_after: float,
                 on_due: Callable[[float], None]) -> None: ...
    def take(self, link: str, t: float, sender: int | None, messages: list[Message], /) -> None: ...
    def __call__(self, heard: Heard, reason: str) -> None: ...
    def mark(self, robot: int, state: int, /) -> None: ...
    def due(self, now: float, /) -> bool: ...
    def tick(self, node: object, /) -> None: ...
    def fold(self) -> tuple[list[tuple[Any, ...]], list[int], int, int, int] | None: ...

class PendingCounts:  # counters.PendingCounts: a Counters' hot counts, folded in before any read
    counts: dict[str, int]
    def fold(self, counters: Counters, /) -> None: ...
    def forget(self) -> None: ...
