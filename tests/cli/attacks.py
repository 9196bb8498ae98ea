"""Hostile participants beside a `vstig bridge`, and robot A -> robot B timed through it (issue 33).

Robot A and robot B are each on a pty radio of the bridge (cobs8). A writes
distinct keys at a steady pace; B's radio notes when each first arrived. Beside
them a participant floods the bridge, as issue 33 found the defaults could not
stand: a radio within its own baud (`RadioFlood`), a local Zenoh session
(`ZenohFlood`), a node on a CAN bus (`can_flood_bridge`). Used by
tests/cli/test_fair_share.py and by `make bench` group `fairness`.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from types import TracebackType

from peers import Listener, PtyPeer, start_vstig, stop

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing

HONEST_KEYS = range(1, 1000)  # robot A's keys (each written once); the floods write keys 1000 and up
FLOOD_FIRST_KEY = 1000
RADIO_FLOOD_RATE = 850  # distinct-key PUTs a second: 10.2 kB/s of cobs8, within a 115,200-baud radio
ZENOH_FLOOD_RATE = 20_000  # messages a second, in samples of 64: 31 times what the bridge sends to one radio
CAN_FLOOD_RATE = 8_000  # frames a second: a classic CAN bus at 1 Mbit/s, full
PROBE_KEY = 999  # A's first write, until B hears it: the bridge is up


def flood_message(i: int, robot: int = 66) -> Message:
    """The flood's i-th message: a new key each time, round after round (a round is newer by one)."""
    span = 0x8000 - FLOOD_FIRST_KEY
    return Message(Op.PUT, FLOOD_FIRST_KEY + i % span, i & 0xFFFF, 1 + i // span, robot)


class Radio:
    """A pty radio whose far end is read all the time (`listener`: when each key first arrived)."""

    def __init__(self) -> None:
        self.peer = PtyPeer()
        self.spec = f"serial:{self.peer.path}?framing=cobs8"
        self.listener = Listener(self.peer)
        self.arrived = self.listener.arrived

    @property
    def heard(self) -> int:
        return self.listener.heard

    def write(self, messages: list[Message]) -> None:
        framing = make_serial_framing("cobs8")
        self.peer.write(b"".join(unit for msg in messages for unit in framing.encode(msg)))

    def close(self) -> None:
        self.listener.close()
        self.peer.close()


def wait_until_relaying(a: Radio, b: Radio, deadline: float = 30.0) -> None:
    """A writes its probe (newer each time) until B hears it: the bridge relays A -> B."""
    end = time.monotonic() + deadline
    stamp = 1
    while PROBE_KEY not in b.arrived:
        if time.monotonic() > end:
            raise AssertionError("the bridge never relayed robot A's probe to robot B")
        a.write([Message(Op.PUT, PROBE_KEY, stamp, stamp, 7)])
        stamp += 1
        time.sleep(0.1)


def honest_delays(a: Radio, b: Radio, count: int = 60, rate: float = 20.0, grace: float = 3.0,
                  first: int = 0) -> list[float | None]:
    """A writes `count` new keys at `rate` a second (from the `first`-th of HONEST_KEYS: a second run in one bridge
    takes others); the delay of each to B (None: not there `grace` s after)."""
    sent = {}
    start = time.perf_counter() + 0.01
    for i, key in enumerate(HONEST_KEYS[first:first + count], start=0):
        pause = start + i / rate - time.perf_counter()
        if pause > 0:
            time.sleep(pause)
        sent[key] = time.perf_counter()
        a.write([Message(Op.PUT, key, i, 1, 7)])
    end = time.monotonic() + grace
    while len([k for k in sent if k in b.arrived]) < count and time.monotonic() < end:
        time.sleep(0.05)
    return [b.arrived[key] - t if key in b.arrived else None for key, t in sent.items()]


def quantile(delays: list[float | None], q: float) -> float:
    """The q-quantile of the delays, a write that never arrived counting as infinitely late."""
    ordered = sorted(d if d is not None else float("inf") for d in delays)
    return ordered[min(int(q * len(ordered)), len(ordered) - 1)]


class RadioFlood:
    """A hostile radio: distinct-key PUTs at `rate` a second, written in 10 ms chunks (within its baud)."""

    def __init__(self, radio: Radio, rate: int = RADIO_FLOOD_RATE) -> None:
        self.radio, self.rate = radio, rate
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._flood, daemon=True)

    def _flood(self) -> None:
        start = time.perf_counter()
        while not self._stop.wait(0.01):
            due = int((time.perf_counter() - start) * self.rate)
            self.radio.write([flood_message(i) for i in range(self.sent, due)])
            self.sent = due

    def __enter__(self) -> RadioFlood:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


_ZENOH_FLOODER = """
import datetime, json, os, sys, time
import zenoh
sys.path.insert(0, {attacks!r})
from attacks import flood_message
from vstig_hw import encode
sessions, publishers = [], []  # the sessions are kept: one dropped is closed
for _ in range({sessions}):
    config = zenoh.Config()  # a stock session, as any local user can open one
    config.insert_json5("connect/endpoints", json.dumps([{endpoint!r}]))
    config.insert_json5("scouting/multicast/enabled", "false")
    if {sessions} > 1:  # each sample stamped with its own session's id: a source of its own at the bridge
        config.insert_json5("timestamping/enabled", "true")
    session = zenoh.open(config)
    sessions.append(session)
    publishers.append(session.declare_publisher("vstig/lab/0/66"))
    while not session.info.peers_zid():
        time.sleep(0.01)
time.sleep(0.5)  # the bridge's subscription reaches this session just after it connects
print("ready", flush=True)
per_sample = 64 if {sessions} == 1 else 1  # many sessions: one message each, in turn

def stamp():  # the stock API stamps any id: a session that never was, per sample
    return zenoh.Timestamp(datetime.datetime.now(datetime.UTC), zenoh.TimestampId(os.urandom(16)))

start, sent = time.perf_counter(), 0
while True:
    due = int((time.perf_counter() - start) * {rate})
    while sent < due:
        payload = b"".join(encode(flood_message(i)) for i in range(sent, sent + per_sample))
        publisher = publishers[sent // per_sample % len(publishers)]
        publisher.put(payload, timestamp=stamp()) if {forge} else publisher.put(payload)
        sent += per_sample
    time.sleep(0.002)
"""


@contextlib.contextmanager
def zenoh_flood(endpoint: str, rate: int = ZENOH_FLOOD_RATE, forge: bool = False, sessions: int = 1
                ) -> Iterator[subprocess.Popen[str]]:
    """A local process on the bridge's zenoh link publishing distinct keys at `rate` messages a second, in samples
    of 64; `forge`: each sample stamped with a new session id; `sessions` > 1: that many sessions connected to the
    bridge, each sample one message from the next session in turn."""
    here = os.path.dirname(os.path.abspath(__file__))
    script = _ZENOH_FLOODER.format(attacks=here, endpoint=endpoint, rate=rate, forge=forge, sessions=sessions)
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True)
    try:
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
        yield process
    finally:
        process.kill()
        process.communicate()


_CAN_BRIDGE = """
import sys, threading, time
sys.path.insert(0, {attacks!r})
import can
from attacks import flood_message
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Node, RoundRobinGet, favour_latency
from vstig_hw.gateway.guard import Guard
from vstig_hw.links import parse
channel = "fair-{pid}"
links = [parse(spec).build(robot_id=200) for spec in ({a!r}, {b!r}, "can:virtual:" + channel)]
node = Node(links, 200, guard=Guard())  # as `vstig bridge` with default options builds it
node.listen(tick=RoundRobinGet())
favour_latency()
stop = threading.Event()
def flood():  # node 66 on the bus, as fast as a full 1 Mbit/s bus carries frames
    bus, codec = can.Bus(interface="virtual", channel=channel), can_framing_for(66)
    start, sent = time.perf_counter(), 0
    while not stop.wait(0.002):
        due = int((time.perf_counter() - start) * {rate})
        for i in range(sent, due):
            bus.send(codec.encode(flood_message(i))[0])
        sent = due
with node:
    if {flooding}:
        threading.Thread(target=flood, daemon=True).start()
    print("ready", flush=True)
    try:
        node.wait_closed()  # the Node runs itself until Ctrl-C
    except KeyboardInterrupt:
        pass
    print(node.summary(), file=sys.stderr)
"""


@contextlib.contextmanager
def can_flood_bridge(a: Radio, b: Radio, flooding: bool, rate: int = CAN_FLOOD_RATE) -> Iterator[None]:
    """A gateway process joining radios A and B and a CAN bus (python-can's virtual bus, which lives in one
    process: the gateway's), where node 66 floods at `rate` frames a second if `flooding`."""
    here = os.path.dirname(os.path.abspath(__file__))
    script = _CAN_BRIDGE.format(attacks=here, pid=os.getpid(), a=a.spec, b=b.spec, rate=rate, flooding=flooding)
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
        yield
    finally:
        process.send_signal(2)
        process.communicate(timeout=20)


class Bridge:
    """`vstig bridge` on the given link specs (and options, if any: the defaults otherwise) as robot 200, stopped on
    exit; `stderr` has its counters then."""

    def __init__(self, *args: str) -> None:
        self.process = start_vstig("bridge", *args, "--robot-id", "200")
        self.stderr = ""

    def __enter__(self) -> Bridge:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.stderr = stop(self.process)[1]
        if kind is not None:  # the test failed inside: what the bridge said goes into pytest's report
            print(f"bridge exited {self.process.returncode}; its stderr:\n{self.stderr[-4000:]}", file=sys.stderr)

