"""ZenohTransport: an embedded Zenoh session that moves samples, and survives the network going away.

Units are `ZenohSample`s (key, payload). What the session's subscriber hears
from other sessions is handed over from Zenoh's callback thread to whoever asked
(`deliver_to`: a gateway's readers, with no queue between), else queued and
handed out by `read`; `write` publishes a sample under its key, one publisher per key.

Zenoh keeps its own links alive: a peer re-dials its `connect=` endpoints with
backoff, forever. What this transport adds is what a user must see: when the
session has no peer or router left (or none ever came), that is logged once and
counted (`lost`, `unreachable`), and its return too (`reconnects`). A client
whose router is down at start cannot even open a session: then the session is
reopened here with exponential backoff from `read`, as the CAN transport does.
A session that dials (`connect=`, or a client) and reaches nobody names the endpoints
(`unreached`: in that line, and in `put`, `get` and `join`'s errors). A listener's peers
come and go (a `vstig put` leaves when done): the last one leaving is an info line, not a loss.

A listener port the caller picked for us (`rebind`) may be taken by another
program before the session binds it: then the session opens on a fresh port,
logged once, and `listening` names the port really bound.

Congestion control is chosen by the caller: BLOCK where losing a sample loses
data (replay, put), DROP for the gateway, whose protocol repairs losses and whose
other links must not stall behind a slow network (docs/how-to/many-pcs.md).

Bounded input: a sample whose payload is above `max_sample` bytes (MAX_SAMPLE,
64 KiB, by default) is refused in Zenoh's callback before it is copied or decoded
(`rx_oversize`, logged once); samples queued for `read` hold at most INBOX_LIMIT
bytes, beyond which a flooding peer's samples are dropped (`rx_overflow`). Samples
handed over from the callback wait for no queue: a flood waits in Zenoh's own
buffers, which drop under congestion.

Who sent a sample (`ZenohSample.source`, what `--source-rate` and the outlets' fair
share key on) is the id stamped on it, but only when that id is a session
connected to ours: the stamp is the publisher's claim (the stock API sets any id
per sample), while the sessions connected to ours are transports Zenoh opened
(and authenticated, where the config asks), which a peer cannot make up per
sample. A sample stamped with any other id (made up, unstamped and stamped here,
or relayed through a router from a session beyond it) has no source of its own:
None, the link as one source.

Counters: `rx`, `tx` (samples), `tx_unheard` (published while no other session subscribed),
`tx_dropped`, `rx_oversize`, `rx_overflow`, `lost`, `unreachable`, `reconnects`; the clock's answers refused
(zenoh_clock): `clock_malformed`, `clock_repeated`, `clock_peers_over`.
"""

from __future__ import annotations

import collections
import ctypes
import logging
import os
import stat
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from ..framing.zenoh import MAX_SAMPLE, ZenohSample
from ..wakeup import Wakeup
from ..wire import MESSAGE_SIZE
from .base import DeviceTransport, DeviceUnreachable, TransportError, one_line
from .zenoh_clock import ZenohClock

__all__ = ["MMAP_THRESHOLD", "ZenohTransport", "free_big_blocks_at_once"]

log = logging.getLogger(__name__)

_DRAIN_LIMIT = 512  # samples taken per read() after the first, so a busy swarm cannot starve the loop
_DRAIN_BYTES = 4 * 1024  # payload bytes taken per read() (at least one sample): ~512 messages of loop work
INBOX_LIMIT = 1024 * 1024  # payload bytes heard and not yet read; beyond, a sample is dropped (rx_overflow)
_PEER_POLL_S = 1.0  # how often to ask the session whether any peer or router is connected
_UNREACHABLE_AFTER_S = 3.0  # a session told to connect that has found nobody by then is reported
_FIRST_PEER_WAIT_S = 3.0  # open() waits this long for a peer it was told to connect to, so a first put is heard
_UNREACHABLE_MARK = "Unable to connect"  # Zenoh's words when a client finds no router at all
_IN_USE_MARKS = ("Address already in use", "os error 10048")  # a listener's port taken (POSIX, Windows)
_REBIND_TRIES = 5  # fresh ports tried after the picked one was taken, before giving up
MMAP_THRESHOLD = 32 * 1024  # bytes: glibc maps blocks this large apart and unmaps them when freed
_M_MMAP_THRESHOLD = -3  # mallopt's parameter number (malloc.h)
_allocator_set = False


def free_big_blocks_at_once() -> None:
    """Have glibc's malloc return blocks of MMAP_THRESHOLD bytes or more to the system when they are freed, once
    per process, before Zenoh's threads allocate (DECISIONS.md, "What a Zenoh peer can make a gateway hold").

    glibc's own threshold starts at 128 KiB and climbs to 32 MiB after the first big block is freed, so a
    flood's 64 KiB batches came from Zenoh's threads' arenas and stayed there after the peers left (+60 MB over
    five floods of 60 kB samples; +13 MB with this). A user's MALLOC_MMAP_THRESHOLD_ is theirs; other C
    libraries have no mallopt and are left as they are.
    """
    global _allocator_set
    if _allocator_set:
        return
    _allocator_set = True
    try:
        glibc = os.confstr("CS_GNU_LIBC_VERSION") is not None
    except (ValueError, OSError):  # not glibc, or not a POSIX system
        glibc = False
    if glibc and "MALLOC_MMAP_THRESHOLD_" not in os.environ:
        ctypes.CDLL(None).mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)


class ZenohTransport(DeviceTransport[ZenohSample, zenoh.Session]):
    """A Zenoh session as a Transport[ZenohSample]."""

    device_word = "Zenoh session"
    reopen_on_write = False  # opening a session may take seconds: only `read` retries it
    clock: ZenohClock | None  # answers clock queries and measures the peers' clocks over this session (or None)

    def __init__(
        self,
        make_config: Callable[[], zenoh.Config],
        subscription: str,
        *,
        name: str,
        block: bool = False,
        expects_peer: bool = False,
        connecting: tuple[str, ...] = (),
        listening: tuple[str, ...] = (),
        reaches: str = "",
        rebind: Callable[[], tuple[str, ...]] | None = None,
        backoff: tuple[float, float] = (0.5, 10.0),
        peer_wait: float | None = None,
        max_sample: int = MAX_SAMPLE,
        clock: ZenohClock | None = None,
    ) -> None:
        if max_sample < MESSAGE_SIZE:
            raise ValueError(f"max_sample must allow one {MESSAGE_SIZE}-byte message, got {max_sample}")
        super().__init__(name, backoff)
        self.max_sample = max_sample  # payload bytes: a bigger sample is refused before it is copied or decoded
        self.clock = clock  # answers clock queries and measures the peers' clocks over this session (or None)
        self.listening = listening  # the endpoints it listens on (a free loopback port by default)
        self._reaches = reaches  # where else it reaches (connects, scouts), for the start line
        self._rebind = rebind  # new endpoints to listen on, when those picked for us were taken
        self.subscription = subscription
        self.congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self._make_config = make_config
        self._expects_peer = expects_peer  # told to connect somewhere: finding nobody is worth a line
        self._connecting = connecting  # the endpoints it dials, named when it reaches nobody
        # How long open() may take in all while it waits for that peer (a one-shot command's budget bounds it).
        self._peer_wait = _FIRST_PEER_WAIT_S if peer_wait is None else peer_wait
        self._lock = threading.Lock()  # session changes (read thread) against publishing (loop thread)
        self._subscriber: Any = None
        self._transports: Any = None  # the listener that keeps `_connected` up to date
        self._connected: frozenset[str] = frozenset()  # ids of the sessions connected to ours: verified sources
        self._connected_lock = threading.Lock()
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._inbox: collections.deque[ZenohSample] = collections.deque()  # appended by zenoh, read by `read`
        self._arrived = Wakeup()  # given with every sample appended: `read` waits for it
        self._deliver: Callable[[list[ZenohSample]], None] | None = None  # see deliver_to
        self._inbox_bytes = 0  # payload bytes in _inbox
        self._inbox_lock = threading.Lock()
        self._told_oversize = False
        self._opened_at = 0.0
        self._next_poll = 0.0
        self._had_peer = False
        self._reported_alone = False
        self._rebound = False  # the fresh-port line is logged once

    # -- lifecycle -----------------------------------------------------------
    def open(self) -> None:
        """Open the session; a bad configuration raises TransportError, an unreachable router is retried."""
        self._opened_at = time.monotonic()
        super().open()
        if self._expects_peer and self.connected:
            self._await_peer(self._opened_at + self._peer_wait - time.monotonic())
        self._next_poll = time.monotonic() + _PEER_POLL_S  # not at once: `join` raises for nobody reached instead

    def _await_peer(self, seconds: float) -> None:
        """Wait (briefly) for the peer or router we connect to, so what we send first is not sent to nobody."""
        session, end = self._device, time.monotonic() + seconds
        while session is not None and time.monotonic() < end:
            info = session.info
            if info.peers_zid() or info.routers_zid():
                self._had_peer = True
                time.sleep(0.05)  # its subscriptions arrive right after the session opens
                return
            time.sleep(0.02)

    @property
    def about(self) -> str:
        """Where it listens and connects, for the start line (print it after open: the port may change then)."""
        listening = f"listening on {', '.join(self.listening)}" if self.listening else ""
        return "; ".join(filter(None, (listening, self._reaches)))

    @property
    def unreached(self) -> str | None:
        """While a session told to connect has no peer or router: where it dials, named, and what is known of why."""
        if not self._expects_peer or self._peers_now():
            return None
        if not self._connecting:  # a client with no connect=: it looks for a router by scouting
            return "found no Zenoh router (no connect= names one; scouting found none)"
        where = ", ".join(endpoint + _local_reason(endpoint) for endpoint in self._connecting)
        return (f"reached nobody at connect={where}: is it up, and does it accept our certificates and "
                "credentials?")

    def _peers_now(self) -> int | None:
        """Peers and routers connected now; None when the session cannot tell (closing)."""
        session = self._device
        if session is None:
            return 0
        try:
            info = session.info
            return len(info.peers_zid()) + len(info.routers_zid())
        except zenoh.ZError:
            return None

    @property
    def session(self) -> zenoh.Session | None:
        """The Zenoh session while open (for diagnostics and tests)."""
        return self._device

    # -- the device calls ------------------------------------------------------
    def _open_device(self) -> zenoh.Session:
        tries = 1 + (_REBIND_TRIES if self._rebind else 0)
        session = None
        for attempt in range(tries):
            session = self._open_session(may_rebind=attempt < tries - 1)
            if session is not None:
                break
        assert session is not None  # the last try raises rather than return None
        try:
            subscriber = session.declare_subscriber(self.subscription, self._heard,
                                                    allowed_origin=zenoh.Locality.REMOTE)
        except zenoh.ZError as exc:
            session.close()  # type: ignore[no-untyped-call]  # zenoh's stub leaves close() untyped
            raise TransportError(f"{self.name}: cannot subscribe to {self.subscription}: {one_line(exc)}") from None
        self._subscriber = subscriber
        if self.clock is not None:
            self.clock.attach(session, self.counters)
        self._connected = frozenset()
        self._transports = session.info.declare_transport_events_listener(self._transport_event, history=True)
        return session

    def _transport_event(self, event: zenoh.TransportEvent) -> None:
        """Zenoh's thread: a session connected to ours (or left): its id names a source from now on (or not)."""
        zid = str(event.transport.zid)
        with self._connected_lock:  # events may come from more than one of Zenoh's threads
            if event.kind == zenoh.SampleKind.PUT:
                self._connected = self._connected | {zid}
            else:
                self._connected = self._connected - {zid}

    def _open_session(self, *, may_rebind: bool) -> zenoh.Session | None:
        """A new session; None if the listener port picked for us was taken (`listening` is then a fresh one)."""
        free_big_blocks_at_once()
        try:
            return zenoh.open(self._make_config())
        except zenoh.ZError as exc:
            reason = one_line(exc).split(" at /", 1)[0]  # Zenoh appends its source location
            if _UNREACHABLE_MARK in reason:
                raise DeviceUnreachable(f"no Zenoh router reachable ({reason}): is it up, and does it accept our "
                                   "certificates and credentials?") from None
            if may_rebind and self._rebind is not None and any(mark in reason for mark in _IN_USE_MARKS):
                taken, self.listening = self.listening, self._rebind()
                if not self._rebound:
                    self._rebound = True
                    log.warning("%s: another program took %s before Zenoh bound it; listening on a fresh port",
                                self.name, ", ".join(taken))
                return None
            raise TransportError(f"{self.name}: cannot open a Zenoh session: {reason}") from None

    def _close_device(self, device: zenoh.Session) -> None:
        with self._lock:  # not while the loop thread publishes
            self._subscriber = None
            self._transports = None
            self._publishers.clear()
            try:
                device.close()  # type: ignore[no-untyped-call]  # zenoh's stub leaves close() untyped
            except zenoh.ZError as exc:  # closing a session whose network is gone may complain
                log.debug("%s: error while closing: %s", self.name, exc)

    def deliver_to(self, deliver: Callable[[list[ZenohSample]], None] | None) -> None:
        """Hand each sample heard to `deliver`, on Zenoh's callback thread, instead of queueing it for `read`.

        None: queue them again. `deliver` must not wait long: Zenoh's receiving waits for it.
        """
        self._deliver = deliver

    def _heard(self, sample: zenoh.Sample) -> None:
        """Zenoh's callback thread: hand the sample on (`deliver_to`), or queue it for `read`."""
        size = len(sample.payload)
        if size > self.max_sample:  # refused before a byte of it is copied or decoded
            self.counters["rx_oversize"] += 1
            if not self._told_oversize:
                self._told_oversize = True
                log.warning("%s: refused a %d-byte sample on %s (the limit is %d bytes: max_sample=); counting "
                            "others as rx_oversize", self.name, size, sample.key_expr, self.max_sample)
            return
        stamp = sample.timestamp  # the publishing session's id, where it stamps (ours do: vstig_hw.links.zenoh)
        claimed = None if stamp is None else str(stamp.get_id())
        heard = ZenohSample(str(sample.key_expr), sample.payload.to_bytes(),
                            claimed if claimed in self._connected else None)
        deliver = self._deliver
        if deliver is not None:  # straight on, from this thread: it waits for the gateway, not a queue
            self.counters["rx"] += 1
            deliver([heard])
            return
        with self._inbox_lock:
            if self._inbox_bytes + size > INBOX_LIMIT:  # the reader is behind: a flood waits no further
                self.counters["rx_overflow"] += 1
                return
            self._inbox_bytes += size
        self._inbox.append(heard)
        self._arrived.set()

    # -- moving samples ------------------------------------------------------
    def _read_device(self, device: zenoh.Session, timeout: float) -> list[ZenohSample]:
        samples: list[ZenohSample] = []
        taken = 0
        inbox = self._inbox
        if not inbox:
            self._arrived.wait(timeout)
        while inbox and len(samples) <= _DRAIN_LIMIT and taken < _DRAIN_BYTES:  # deque.popleft is atomic
            samples.append(inbox.popleft())
            taken += len(samples[-1].payload)
        if taken:
            with self._inbox_lock:
                self._inbox_bytes -= taken
        self._watch_peers(device)
        if self.clock is not None:
            self.clock.probe(device)
        return samples

    def write_nowait(self, unit: ZenohSample) -> ZenohSample | None:
        """Publish now if congestion control drops rather than blocks (a gateway's); else the sample, to wait."""
        if self.congestion != zenoh.CongestionControl.DROP:
            return unit
        self.write(unit)
        return None

    def _write_device(self, device: zenoh.Session, unit: ZenohSample) -> None:
        with self._lock:
            session = self._device
            if session is None:  # closed meanwhile
                self.counters["tx_dropped"] += 1
                return
            publisher = self._publishers.get(unit.key)
            try:
                if publisher is None:
                    publisher = self._publishers[unit.key] = session.declare_publisher(
                        unit.key, congestion_control=self.congestion, allowed_destination=zenoh.Locality.REMOTE)
                status: Any = publisher.matching_status  # a MatchingStatus (the stub says bool)
                if not status.matching:  # no other session subscribes: the sample reaches nobody
                    self.counters["tx_unheard"] += 1
                publisher.put(unit.payload)
            except zenoh.ZError as exc:
                self.counters["tx_dropped"] += 1
                if self.last_error is None:
                    self.last_error = one_line(exc)
                    log.warning("%s: cannot publish on %s: %s", self.name, unit.key, self.last_error)
                return
            self._sent()

    # -- the network coming and going -----------------------------------------
    def _watch_peers(self, session: zenoh.Session) -> None:
        now = time.monotonic()
        if now < self._next_poll:
            return
        self._next_poll = now + _PEER_POLL_S
        others = self._peers_now()
        if others is None:
            return
        if others and not self._had_peer:
            self._had_peer = True
            if self._reported_alone:
                self.counters["reconnects"] += 1
                log.warning("%s: Zenoh peers reachable again (%d)", self.name, others)
                self._reported_alone = False
        elif not others and self._had_peer:
            self._had_peer = False
            if self._expects_peer:  # what it dials is gone
                self._reported_alone = True
                self.counters["lost"] += 1
                log.warning("%s: lost every Zenoh peer; Zenoh reconnects with backoff", self.name)
            else:  # peers come to a listener and leave when done (a one-shot `vstig put`): nothing was lost
                log.info("%s: the last Zenoh peer left; listening on %s", self.name, ", ".join(self.listening))
        elif not others and self._expects_peer and not self._reported_alone \
                and now - self._opened_at > _UNREACHABLE_AFTER_S:
            self._reported_alone = True
            self.counters["unreachable"] += 1
            log.warning("%s: %s; Zenoh keeps retrying with backoff", self.name, self.unreached)


def _local_reason(endpoint: str) -> str:
    """Why a unix socket endpoint cannot answer, where its path shows it (" (no such socket file)"); else ""."""
    protocol, _, address = endpoint.partition("/")
    if protocol != "unixsock-stream":
        return ""
    path = address.split("?", 1)[0].split("#", 1)[0]
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return " (no such socket file)"
    except OSError as exc:
        return f" ({exc.strerror})"
    return "" if stat.S_ISSOCK(mode) else " (not a socket)"
