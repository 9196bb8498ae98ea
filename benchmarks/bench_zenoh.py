"""Gateways on many PCs (issue: federation over Zenoh): latency, throughput and bytes, beside bare Zenoh."""

from __future__ import annotations

import json
import multiprocessing
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import can

from .bench_cli import _numbered, _p, _radio_listener, _raw_pty, _sleep_paced, _tag
from .registry import Result, benchmark
from .zenoh_peer import BARE_KEY, bare_session, collect, free_port, start_receiver

_ROOT = Path(__file__).parents[1]
VSTIG = str(Path(sys.executable).with_name("vstig"))


def _wait_for_peer(link: object, seconds: float = 20.0) -> None:
    session = link.transport.session  # type: ignore[attr-defined]
    end = time.monotonic() + seconds
    while not session.info.peers_zid() and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(1.0)  # the far end's subscriptions arrive after its session


class _TimedRadio:
    """A cobs8 pty radio whose far end, a forked process, timestamps each message that arrives. Make it before
    this process opens any Zenoh session or starts a gateway thread: a fork copies only the calling thread."""

    def __init__(self, count: int) -> None:
        self.master, self.slave, self.path = _raw_pty()
        fork = multiprocessing.get_context("fork")
        self._arrivals, done = fork.Pipe(duplex=False)
        self._listener = fork.Process(target=_radio_listener, args=(self.master, count, done, 3.0))
        self._listener.start()

    def latencies(self, sent: list[float]) -> list[float]:
        """Per message that arrived, sorted: its arrival less `sent[i]`, the time message i was sent."""
        arrived = self._arrivals.recv()
        self._listener.join()
        return sorted(arrived[_tag(i)] - sent[i] for i in range(len(sent)) if _tag(i) in arrived)

    def close(self) -> None:
        os.close(self.master)
        os.close(self.slave)


def _can_frames(count: int) -> list[can.Message]:
    from vstig_hw.framing.can import can_framing_for

    codec = can_framing_for(7)
    return [codec.encode(_numbered(i))[0] for i in range(count)]


def _gateway_hop(rate_hz: int, count: int) -> list[float]:
    """A frame into gateway A's CAN link (in this process) to the message out of gateway B's pty link.

    B is a real `vstig bridge` process (zenoh + a cobs8 pty radio); the radio's far end times arrivals.
    """
    from vstig_hw.gateway import Node, favour_latency
    from vstig_hw.links import parse

    radio = _TimedRadio(count)
    port = free_port()
    far = subprocess.Popen([VSTIG, "bridge", f"zenoh:bench?connect=tcp/127.0.0.1:{port}", f"serial:{radio.path}",
                            "--robot-id", "202", "--budget", "20000", "--no-refresh"],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    channel = f"bench-zenoh-{os.getpid()}-{rate_hz}"
    robot = can.Bus(interface="virtual", channel=channel)
    frames = _can_frames(count)
    links = [parse(f"can:virtual:{channel}").build("bus", robot_id=201),
             parse(f"zenoh:bench?listen=tcp/127.0.0.1:{port}").build("zenoh", robot_id=201)]
    node = Node(links, 201, budget=20000, period=0.1)
    favour_latency()
    try:
        node.open()  # its loop runs on its own thread
        _wait_for_peer(links[1])
        return radio.latencies(_sleep_paced(count, rate_hz, lambda i: robot.send(frames[i])))
    finally:
        node.close()
        robot.shutdown()
        far.terminate()
        far.wait(timeout=20)
        radio.close()


def _bare_hop(rate_hz: int, count: int) -> list[float]:
    """A bare Zenoh put of one 8-byte sample to a subscriber in another process."""
    from vstig_hw.wire import encode

    port = free_port()
    session = bare_session(listen=f"tcp/127.0.0.1:{port}")
    publisher = session.declare_publisher(BARE_KEY)
    receiver = start_receiver("bare", f"tcp/127.0.0.1:{port}", count)
    time.sleep(1.0)
    payloads = [encode(_numbered(i)) for i in range(count)]
    sent = _sleep_paced(count, rate_hz, lambda i: publisher.put(payloads[i]))
    arrived = collect(receiver)
    session.close()  # type: ignore[no-untyped-call]
    return sorted(arrived[_tag(i)] - sent[i] for i in range(count) if _tag(i) in arrived)


def _bare_path_hop(rate_hz: int, count: int) -> list[float]:
    """The gateways' path with bare hops: a CAN frame in a thread here -> a bare Zenoh put -> a process that writes
    each message to a cobs8 pty radio, whose far end times arrivals as in `_gateway_hop`."""
    radio = _TimedRadio(count)
    port = free_port()
    session = bare_session(listen=f"tcp/127.0.0.1:{port}")
    publisher = session.declare_publisher(BARE_KEY)
    far = subprocess.Popen([sys.executable, "-m", "benchmarks.zenoh_peer", "relay", f"tcp/127.0.0.1:{port}",
                            radio.path], stdout=subprocess.PIPE, text=True, cwd=_ROOT)
    channel = f"bench-zenoh-bare-{os.getpid()}-{rate_hz}"
    robot = can.Bus(interface="virtual", channel=channel)
    bus = can.Bus(interface="virtual", channel=channel)
    frames = _can_frames(count)
    stop = threading.Event()

    def hop() -> None:
        while not stop.is_set():
            frame = bus.recv(0.05)
            if frame is not None:
                publisher.put(bytes(frame.data))

    worker = threading.Thread(target=hop, daemon=True)
    worker.start()
    try:
        assert far.stdout is not None and far.stdout.readline().strip() == "ready"
        time.sleep(1.0)  # its subscription reaches our session
        return radio.latencies(_sleep_paced(count, rate_hz, lambda i: robot.send(frames[i])))
    finally:
        stop.set()
        worker.join(timeout=5)
        far.kill()
        far.wait(timeout=20)
        bus.shutdown()
        robot.shutdown()
        session.close()  # type: ignore[no-untyped-call]
        radio.close()


@benchmark("zenoh")
def cross_gateway_latency() -> Iterator[Result]:
    """CAN into gateway A, zenoh to gateway B (a `vstig bridge` process), out of B's pty radio; p50/p99.

    Beside bare Zenoh (one put to one subscriber), the same path with bare hops (CAN -> Zenoh in a thread,
    Zenoh -> pty in a process): the first anchor has no CAN and no pty hop, the second has every hop the
    gateways have, so it tells what the gateways themselves add."""
    for rate_hz in (1000, 5000):
        count = 2 * rate_hz
        ours = _gateway_hop(rate_hz, count)
        bare = _bare_hop(rate_hz, count)
        bare_path = _bare_path_hop(rate_hz, count)
        for q, label in ((0.5, "p50"), (0.99, "p99")):
            yield Result(f"zenoh.gateway_latency_{rate_hz}hz_{label}", _p(ours, q) * 1e3, "ms",
                         f"bare Zenoh put->subscriber {label}", _p(bare, q) * 1e3)
            yield Result(f"zenoh.gateway_latency_{rate_hz}hz_{label}_vs_bare_path", _p(ours, q) * 1e3, "ms",
                         f"CAN->Zenoh->pty, bare hops {label}", _p(bare_path, q) * 1e3)
        yield Result(f"zenoh.gateway_delivered_{rate_hz}hz", len(ours) / count * 100, "%", "offered", 100.0)


@benchmark("zenoh")
def throughput_and_bytes() -> Iterator[Result]:
    """One zenoh link to another process, batches of 64 (a gateway's flush), beside bare 8-byte samples.

    As root the pair runs in a network namespace of its own (`unshare -n`), so its loopback
    counts only their bytes: TCP/IP and Zenoh headers included, per message delivered.
    """
    count, batch = 200_000, 64
    command = [sys.executable, "-m", "benchmarks.zenoh_peer", "throughput", str(count), str(batch)]
    env = dict(os.environ)
    if os.geteuid() == 0:
        command = ["unshare", "-n", *command]
        env["VSTIG_BENCH_NETNS"] = "1"
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=_ROOT, env=env, check=True)
    figures = json.loads(done.stdout)
    yield Result("zenoh.throughput_batched", figures["ours"], "msg/s", "bare Zenoh 8-byte samples/s", figures["bare"])
    yield Result("zenoh.throughput_vs_goal", figures["ours"], "msg/s", "goal 50,000 msg/s", 50_000.0)
    yield Result("zenoh.throughput_delivered", figures["ours_delivered"] * 100, "%", "offered", 100.0)
    if figures["bytes_per_msg"] is not None:
        yield Result("zenoh.network_bytes_per_msg", figures["bytes_per_msg"], "B/msg", "8-byte wire message", 8.0)
    else:
        print("zenoh.network_bytes_per_msg: needs root (a private network namespace to count loopback bytes)",
              file=sys.stderr)
