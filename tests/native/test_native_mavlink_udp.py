"""The compiled delivery reading a MAVLink UDP socket itself (Path.pump: recvmmsg, the sources into a compiled
UdpPeers, a datagram that is not one frame cut as the transport cuts it) and its outlet sending to it, against the
pure-Python Node reading and sending through MavlinkUdpTransport: real sockets on loopback, the same hostile
datagrams from the same sources to each, signed and unsigned. Both must count the same drops (the transport's and
the framing's: drop_unsigned, drop_signature, drop_replay, other payload types, MAVLink 1...), hand the guard the
same messages from the same senders, keep the same peers (at most MAX_PEERS, the most recently heard), and send the
same messages to each of them. UdpPeers' twin is held equal to the Python one on random calls.
"""

from __future__ import annotations

import random
import socket
import time
from collections import Counter
from collections.abc import Iterator
from types import ModuleType
from typing import Any

import pytest
import test_native_mavlink as mavlink_twins  # modules of helpers, not their tests
from test_native_xbee import RecordingGuard

from vstig_hw import Message
from vstig_hw.framing.mavlink import MavlinkFraming, Signing
from vstig_hw.gateway.compiled import port_for
from vstig_hw.gateway.node import Mode, Node
from vstig_hw.links.link import Link
from vstig_hw.transports.mavlink import MAX_PEERS, MavlinkUdpTransport, UdpPeers

KEY = mavlink_twins.KEY
SOURCES = MAX_PEERS + 2  # more drones than a udpin link keeps peers


def _link(mode: str, address: tuple[str, int], keyed: bool, name: str) -> tuple[Link[bytes], MavlinkUdpTransport]:
    framing = MavlinkFraming(4, 191, signing=Signing(KEY) if keyed else None)
    transport = MavlinkUdpTransport(mode, address, heartbeat=framing.heartbeat,
                                    stamp=framing.in_order if keyed else None, name=name)
    return Link(name, transport, framing), transport


def _local(transport: MavlinkUdpTransport) -> Any:
    """The address the transport's open socket sends from."""
    device = transport.compiled_handle().device
    assert device is not None
    return device.getsockname()


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class Side:
    """One Node (pure or compiled): a udpin link the drones send to, a udpout link to a router socket."""

    def __init__(self, compiled: bool, keyed: bool) -> None:
        self.router = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.router.bind(("127.0.0.1", 0))
        self.into = ("127.0.0.1", _free_port())
        self.guard = RecordingGuard()
        (drones, self.drones), (up, self.up) = (_link("udpin", self.into, keyed, "drones"),
                                                _link("udpout", self.router.getsockname(), keyed, "up"))
        links = [drones, up]
        self.node = Node(links, 9, mode=Mode.RAW, budget=None, guard=self.guard, pure=not compiled)  # all at once

    def close(self) -> None:
        self.node.close()
        self.router.close()


@pytest.fixture
def drones() -> Iterator[list[socket.socket]]:
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(SOURCES)]
    for sock in socks:
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
    yield socks
    for sock in socks:
        sock.close()


def _wait(what: str, done: Any) -> None:
    deadline = time.monotonic() + 10
    while not done():
        assert time.monotonic() < deadline, what
        time.sleep(0.005)


def _datagrams(seed: int, keyed: bool) -> list[bytes]:
    """Hostile units as datagrams: mostly one each, some glued two or three to a datagram (cut by the transport)."""
    rng = random.Random(seed)
    units = mavlink_twins.hostile_units(seed, keyed, 160)
    datagrams: list[bytes] = []
    while units:
        take = 1 if rng.random() < 0.8 else rng.randrange(2, 4)
        datagrams.append(b"".join(units[:take]))
        del units[:take]
    return [datagram for datagram in datagrams if datagram]


def _heard(sock: socket.socket, reader: MavlinkFraming) -> dict[Any, Counter[Message]]:
    """The messages of the broadcast TUNNELs that reached `sock`, by the address they came from (HEARTBEATs and the
    rest left aside); `reader` checks signatures and timestamps where it has the key."""
    sock.setblocking(False)
    heard: dict[Any, Counter[Message]] = {}
    while True:
        try:
            data, source = sock.recvfrom(65536)
        except BlockingIOError:
            return heard
        heard.setdefault(source, Counter()).update(reader.feed(data))


def _up_to(router: socket.socket, reader: MavlinkFraming) -> Counter[Message]:
    return sum(_heard(router, reader).values(), Counter())


def _received(transport: MavlinkUdpTransport) -> dict[str, int]:
    return {name: n for name, n in transport.counters.items() if n and name not in ("tx_bytes", "tx", "heartbeats")}


@pytest.mark.parametrize("keyed", [False, True])
def test_the_compiled_udp_read_and_send_equal_the_transports(compiled: ModuleType, drones: list[socket.socket],
                                                             keyed: bool) -> None:
    rng = random.Random(int(keyed))
    sides = [Side(compiled=False, keyed=keyed), Side(compiled=True, keyed=keyed)]
    pure, fast = sides
    try:
        for side in sides:
            side.node.open()
        assert type(fast.drones.peers) is compiled.UdpPeers and type(pure.drones.peers) is UdpPeers  # read in C
        assert [port_for(link) for link in fast.node.links] == ["udp", "udp"]  # and written in C, signed or not
        sent = 0
        up: list[Counter[Message]] = [Counter(), Counter()]  # what the drones sent went up to each router
        readers = [MavlinkFraming(9, 1, signing=Signing(KEY) if keyed else None) for _ in sides]  # the routers'
        datagrams = _datagrams(rng.randrange(1 << 30), keyed)
        at = 0
        while at < len(datagrams):  # bursts from one drone or several, read in one recvmmsg or more
            burst = datagrams[at:at + rng.randrange(1, 12)]
            at += len(burst)
            for datagram in burst:
                drone = drones[rng.randrange(SOURCES)]
                for side in sides:
                    drone.sendto(datagram, side.into)
            sent += len(burst)
            _wait("a node did not read what the drones sent",
                  lambda sent=sent: all(side.drones.counters["rx_datagrams"] >= sent for side in sides))
            for side, heard, reader in zip(sides, up, readers, strict=True):  # as it comes: a buffer holds ~150
                heard.update(_up_to(side.router, reader))
        ahead = mavlink_twins.T0 + 3600  # a signing clock past the drones' (theirs is T0 on)
        batch = mavlink_twins._messages(rng, 20)
        for side in sides:  # the router's turn: what it sends goes to the live peers of the udpin link
            framing = MavlinkFraming(30, 1, signing=Signing(KEY, clock=lambda: ahead) if keyed else None)
            side.router.sendto(b"".join(framing.encode_batch(batch)), _local(side.up))
        _wait("the router's messages did not reach the drones",
              lambda: all(side.node.links[0].counters["out"] >= 20 for side in sides))
        time.sleep(0.2)
        now = time.monotonic()
        assert fast.drones.peers is not None and pure.drones.peers is not None
        assert fast.drones.peers.live(now) == pure.drones.peers.live(now)
        assert len(pure.drones.peers) == MAX_PEERS
        assert _received(fast.drones) == _received(pure.drones)
        assert dict(fast.node.links[0].framing.drops) == dict(pure.node.links[0].framing.drops)
        assert fast.guard.asked == pure.guard.asked
        assert any(sender is not None for sender, _ in pure.guard.asked)
        reasons = set(pure.node.links[0].framing.drops) | set(_received(pure.drones))
        # unsigned TUNNELs of another payload_type are refused before their type is looked at when keyed
        assert {"mavlink1", "crc", "drop_noise"} | ({"unsigned", "signature", "replay"} if keyed
                                                    else {"other_payload_type"}) <= reasons
        for side, heard, reader in zip(sides, up, readers, strict=True):
            heard.update(_up_to(side.router, reader))
        assert up[1] == up[0] and up[0].total() > 50
        # every frame either side sent (TUNNELs, HEARTBEATs) was taken: signed, and in timestamp order
        assert [set(reader.drops) for reader in readers] == [{"other_message"}, {"other_message"}]
        assert pure.drones.peers is not None
        live = set(pure.drones.peers.live(time.monotonic()))
        for drone in drones:  # the router's 20 messages from each side's udpin link, to its live peers alone
            by_source = _heard(drone, MavlinkFraming(9, 1))
            want = Counter(batch) if drone.getsockname() in live else Counter()
            assert [by_source.get(side.into, Counter()) for side in sides] == [want, want], drone.getsockname()
    finally:
        for side in sides:
            side.close()


def _peer_calls(seed: int) -> list[tuple[str, Any, float]]:
    rng = random.Random(seed)
    pool = [("127.0.0.1", port) for port in range(5000, 5012)] + [("::1", 6000, 0, 0), ("10.0.0.7", 5000)]
    now, calls = 0.0, []
    for _ in range(300):
        now += rng.choice((0.0, 0.001, 0.5, 3.0, 11.0))
        calls.append(("heard", rng.choice(pool), now) if rng.random() < 0.7 else ("live", None, now))
    return calls


@pytest.mark.parametrize("seed", range(20))
def test_udp_peers_twin_equals_the_python_one(compiled: ModuleType, seed: int) -> None:
    most, timeout = random.Random(seed).choice(((MAX_PEERS, 10.0), (1, 10.0), (3, 2.0)))
    python, twin = UdpPeers(most, timeout), compiled.UdpPeers(most, timeout)
    for call, address, now in _peer_calls(seed):
        if call == "heard":
            python.heard(address, now)
            twin.heard(address, now)
        else:
            assert twin.live(now) == python.live(now)
        assert len(twin) == len(python) <= most


def test_a_python_udp_peers_that_keeps_a_peer_s_first_place_is_caught(compiled: ModuleType,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    # the twin test can fail: a re-heard address that keeps its place (so the wrong peer is forgotten first)
    def heard_in_place(self: UdpPeers, address: Any, now: float) -> None:
        self._until[address] = now + self.timeout
        if len(self._until) > self.most:
            del self._until[next(iter(self._until))]

    monkeypatch.setattr(UdpPeers, "heard", heard_in_place)
    with pytest.raises(AssertionError):
        for seed in range(20):
            test_udp_peers_twin_equals_the_python_one(compiled, seed)


def test_udp_peers_name_a_bad_address(compiled: ModuleType) -> None:
    with pytest.raises(ValueError, match="numeric IPv4 or IPv6 address, got \\('localhost', 5\\)"):
        compiled.UdpPeers().heard(("localhost", 5), 0.0)
    with pytest.raises(ValueError, match="a UDP peer is \\(host, port"):
        compiled.UdpPeers().heard("127.0.0.1:5", 0.0)
    with pytest.raises(ValueError, match=r"1\.\.4096 peers, got 0"):
        compiled.UdpPeers(0)
