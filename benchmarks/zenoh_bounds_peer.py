"""Two local Zenoh sessions in processes of their own, with vstig's bounds or with Zenoh's defaults
(`python -m benchmarks.zenoh_bounds_peer run SETTING SIZE PINGS FLOOD` prints JSON; `echo SETTING ENDPOINT` is the
far end it starts).

vstig: the config a zenoh: link builds (a peer's sample bounded, shared memory off) and glibc's fixed mmap
threshold (DECISIONS.md, "What a Zenoh peer can make a gateway hold"); zenoh: Zenoh's own defaults (shared memory
on, 1 GiB messages, glibc's dynamic threshold). The far end echoes each ping; the flood goes one way, and a ping
sent after it comes back once the flood has arrived (one reliable link, in order).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import zenoh

from vstig_hw.links.zenoh import ZenohSpec, zenoh_config
from vstig_hw.transports import zenoh as zenoh_transport

from .zenoh_peer import free_port


def _session(setting: str, *, listen: str = "", connect: str = "") -> zenoh.Session:
    if setting == "vstig":
        zenoh_transport.free_big_blocks_at_once()
        config = zenoh_config(ZenohSpec("bench", listen=(listen,) if listen else (),
                                        connect=(connect,) if connect else (), max_sample=64 * 1024))
        if not listen:
            config.insert_json5("listen/endpoints", "[]")
    else:
        config = zenoh.Config()
        config.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
        config.insert_json5("connect/endpoints", json.dumps([connect] if connect else []))
        config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def echo(setting: str, endpoint: str) -> None:
    session = _session(setting, connect=endpoint)
    pong = session.declare_publisher("bench/pong", congestion_control=zenoh.CongestionControl.BLOCK)
    ping = session.declare_subscriber("bench/ping", lambda sample: pong.put(sample.payload))
    flood = session.declare_subscriber("bench/flood", lambda sample: None)
    print("ready", flush=True)
    sys.stdin.read()
    del ping, flood
    session.close()  # type: ignore[no-untyped-call]


def run(setting: str, size: int, pings: int, flood: int) -> dict[str, float]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = _session(setting, listen=endpoint)
    far = subprocess.Popen([sys.executable, "-m", "benchmarks.zenoh_bounds_peer", "echo", setting, endpoint],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=Path(__file__).parents[1])
    assert far.stdout is not None and far.stdout.readline().strip() == "ready"
    back = threading.Event()
    session.declare_subscriber("bench/pong", lambda sample: back.set())
    block = zenoh.CongestionControl.BLOCK
    ping = session.declare_publisher("bench/ping", congestion_control=block)
    out = session.declare_publisher("bench/flood", congestion_control=block)
    payload = b"\x01" * size

    def round_trip() -> float:
        back.clear()
        began = time.perf_counter()
        ping.put(payload)
        if not back.wait(10):
            raise RuntimeError("no pong")
        return time.perf_counter() - began

    while True:  # the far end's subscriptions reach us a little after its session
        back.clear()
        ping.put(payload)
        if back.wait(0.2):
            break
    times = sorted(round_trip() for _ in range(pings))
    began = time.perf_counter()
    for _ in range(flood):
        out.put(payload)
    round_trip()
    rate = flood / (time.perf_counter() - began)
    far.communicate("", timeout=30)
    session.close()  # type: ignore[no-untyped-call]
    return {"p50": statistics.median(times), "p99": times[int(len(times) * 0.99)], "rate": rate}


if __name__ == "__main__":
    if sys.argv[1] == "echo":
        echo(sys.argv[2], sys.argv[3])
    else:
        print(json.dumps(run(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))))
