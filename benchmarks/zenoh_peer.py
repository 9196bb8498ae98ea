"""The far ends of the zenoh benchmarks, each in its own process (`python -m benchmarks.zenoh_peer ...`).

    receive bare|link ENDPOINT COUNT   subscribe (a bare Zenoh session, or a zenoh link as the gateway
                                       builds it), stamp every message's arrival (perf_counter is
                                       system-wide), print {tag: time} as JSON
    relay ENDPOINT PTY                 a bare hop from Zenoh to a cobs8 pty radio: every message of every
                                       sample on BARE_KEY, encoded and written to PTY, until killed
    throughput COUNT BATCH             one process sends COUNT messages to a receiver process, as
                                       batches over a zenoh link and as bare 8-byte samples; prints
                                       messages/s for both and, when it runs in its own network
                                       namespace, the bytes that crossed loopback per message

A message's tag is key << 16 | value (the benchmarks number messages that way).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import zenoh

from vstig_hw.links import parse
from vstig_hw.wire import Message, Op, decode_many, encode

SWARM = "bench"
BARE_KEY = "bench/bare"
IDLE_S = 3.0  # a receiver stops this long after the last arrival


def numbered(i: int) -> Message:
    return Message(Op.PUT, i % 32768, i // 32768, 1, 7)


def tag_of(msg: Message) -> int:
    return msg.key << 16 | msg.value


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def bare_session(listen: str = "", connect: str = "") -> zenoh.Session:
    config = zenoh.Config()
    config.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    config.insert_json5("connect/endpoints", json.dumps([connect] if connect else []))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def receive(mode: str, endpoint: str, count: int) -> dict[int, float]:
    arrived: dict[int, float] = {}
    clock = time.perf_counter
    if mode == "bare":
        session = bare_session(connect=endpoint)

        def heard(sample: zenoh.Sample) -> None:
            stamp = clock()
            for msg in decode_many(sample.payload.to_bytes()):
                arrived.setdefault(tag_of(msg), stamp)

        session.declare_subscriber(BARE_KEY, heard)
        print("ready", flush=True)
        _wait(arrived, count)
        session.close()  # type: ignore[no-untyped-call]
        return dict(arrived)
    link = parse(f"zenoh:{SWARM}?connect={endpoint}").build(robot_id=9, listen_only=True)
    link.open()
    print("ready", flush=True)
    last = clock() + 60
    while len(arrived) < count and clock() < last:
        for heard_msg in link.receive(0.05):
            stamp = clock()
            arrived.setdefault(tag_of(heard_msg.message), stamp)
            last = min(last, stamp + IDLE_S)
    link.close()
    return arrived


def relay(endpoint: str, pty: str) -> None:
    """Zenoh -> cobs8 pty with nothing between: the least a gateway's far side must do."""
    from vstig_hw.framing import make_serial_framing

    cobs8 = make_serial_framing("cobs8")
    fd = os.open(pty, os.O_RDWR | os.O_NOCTTY)
    session = bare_session(connect=endpoint)

    def heard(sample: zenoh.Sample) -> None:
        os.write(fd, b"".join(cobs8.encode(msg)[0] for msg in decode_many(sample.payload.to_bytes())))

    session.declare_subscriber(BARE_KEY, heard)
    print("ready", flush=True)
    while True:
        time.sleep(3600)


def _wait(arrived: dict[int, float], count: int) -> None:
    last_size, idle_since = -1, time.perf_counter()
    end = time.perf_counter() + 60
    while len(arrived) < count and time.perf_counter() < end:
        time.sleep(0.05)
        if len(arrived) != last_size:
            last_size, idle_since = len(arrived), time.perf_counter()
        elif arrived and time.perf_counter() - idle_since > IDLE_S:
            return


def start_receiver(mode: str, endpoint: str, count: int) -> subprocess.Popen[str]:
    process = subprocess.Popen([sys.executable, "-m", "benchmarks.zenoh_peer", "receive", mode, endpoint, str(count)],
                               stdout=subprocess.PIPE, text=True, cwd=Path(__file__).parents[1])
    assert process.stdout is not None and process.stdout.readline().strip() == "ready"
    return process


def collect(process: subprocess.Popen[str]) -> dict[int, float]:
    out, _ = process.communicate(timeout=120)
    return {int(k): v for k, v in json.loads(out).items()}


def _lo_bytes() -> int:
    """Bytes sent on this network namespace's loopback (/proc/net is per namespace; /sys is not here)."""
    for line in Path("/proc/self/net/dev").read_text().splitlines():
        name, _, fields = line.partition(":")
        if name.strip() == "lo":
            return int(fields.split()[8])
    return 0


def _rate(arrived: dict[int, float], sent_at: float) -> float:
    return len(arrived) / (max(arrived.values()) - sent_at) if arrived else 0.0


def throughput(count: int, batch: int) -> dict[str, Any]:
    """Messages/s delivered over a zenoh link (batches, as the gateway sends) and as bare 8-byte samples."""
    own_netns = os.environ.get("VSTIG_BENCH_NETNS") == "1"
    if own_netns:
        subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    messages = [numbered(i) for i in range(count)]
    port = free_port()
    sender = parse(f"zenoh:{SWARM}?listen=tcp/127.0.0.1:{port}").build(robot_id=1)
    sender.open()
    receiver = start_receiver("link", f"tcp/127.0.0.1:{port}", count)
    time.sleep(1.0)  # its session and subscription reach ours
    before = _lo_bytes()
    start = time.perf_counter()
    for first in range(0, count, batch):
        sender.send_many(messages[first:first + batch])
    ours = collect(receiver)
    wire = _lo_bytes() - before
    sender.close()

    session = bare_session(listen=f"tcp/127.0.0.1:{port}")
    publisher = session.declare_publisher(BARE_KEY)
    receiver = start_receiver("bare", f"tcp/127.0.0.1:{port}", count)
    time.sleep(1.0)
    bare_start = time.perf_counter()
    payloads = [encode(m) for m in messages]
    for payload in payloads:
        publisher.put(payload)
    bare = collect(receiver)
    session.close()  # type: ignore[no-untyped-call]
    return {"ours": _rate(ours, start), "ours_delivered": len(ours) / count,
            "bare": _rate(bare, bare_start), "bare_delivered": len(bare) / count,
            "bytes_per_msg": wire / max(len(ours), 1) if own_netns else None}


def main(argv: list[str]) -> None:
    if argv[0] == "receive":
        arrived = receive(argv[1], argv[2], int(argv[3]))
        print(json.dumps(arrived))
    elif argv[0] == "relay":
        relay(argv[1], argv[2])
    elif argv[0] == "throughput":
        print(json.dumps(throughput(int(argv[1]), int(argv[2]))))
    else:
        raise SystemExit(f"unknown role {argv[0]!r}")


if __name__ == "__main__":
    main(sys.argv[1:])
