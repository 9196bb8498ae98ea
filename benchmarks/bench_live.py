"""The live view's cost to the gateway: relay CPU per message with `--foxglove` and one viewer, beside without.

An engine bridge between two python-can virtual buses relays a busy swarm's traffic (50 robots, the
realistic mix). Figures per message heard: the gateway process's CPU (`time.process_time`: its loop, reader threads
and the live view's shipping thread), the gateway loop's own thread (`time.thread_time`: what stands
between a frame heard and its relay; the sender shares it in both runs), and, beside them, what the
live view's server process (the SDK, CDR, table, writes) spends on its own core. The
viewer is Foxglove's own client (tests/live, under Node) subscribed to every channel, in its own
process; without Node and `make test`'s npm install the figure is left out, saying why.
Goal (issue 27): at most 1.2x.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import can

from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway import Mode, Node
from vstig_hw.links.can import can_link

from .bench_wire import realistic_mix
from .registry import Result, benchmark

_N = 20_000
_BATCH = 200  # frames sent before the gateway catches up: a bus delivering in bursts
_CLIENT = Path(__file__).resolve().parents[1] / "tests" / "live" / "foxglove_client.cjs"


def _frames(n: int) -> list[can.Message]:
    framings = [CanFraming(CanIdScheme(), sender) for sender in range(50)]
    return [framings[msg.robot % 50].encode(msg)[0] for msg in realistic_mix(n)]


def engine_bridge(channel: str) -> tuple[Node, can.BusABC, can.BusABC]:
    """An engine Node between two virtual buses (not yet open), the bus a swarm sends on and the one it drains."""
    node = Node([can_link("virtual", channel, robot_id=1), can_link("virtual", channel + "-out", robot_id=1)],
                200, mode=Mode.ENGINE, budget=None)
    return node, can.Bus(interface="virtual", channel=channel), can.Bus(interface="virtual", channel=channel + "-out")


def relay(node: Node, sender: can.BusABC, drain: can.BusABC, frames: list[can.Message]) -> None:
    """Send `frames` in bursts through the open `node`, each burst heard before the next goes."""
    heard = node.links[0].counters
    for at in range(0, len(frames), _BATCH):
        for frame in frames[at:at + _BATCH]:
            sender.send(frame)
        while heard["in"] < at + _BATCH:
            time.sleep(0.001)  # the node's own threads relay it
        while drain.recv(0) is not None:
            pass


def _relay_cpu(frames: list[can.Message], run: int, viewer: bool) -> tuple[float, float, float]:
    """(gateway process, gateway loop thread, live view server process) CPU seconds per message heard by
    an engine bridge, with a live view and a viewer on it or not."""
    node, sender, drain = engine_bridge(f"bench-live-{run}-{viewer}")
    view = client = None
    try:
        if viewer:
            from vstig_hw.live.view import LiveView

            view = LiveView(node, port=0)
            view.open()
            client = subprocess.Popen([shutil.which("node") or "node", str(_CLIENT), view.url],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            subscribed = threading.Event()

            def read(stream: IO[str]) -> None:  # all of it: a viewer whose output backs up stops reading
                for line in stream:
                    if '"topic":"/vstig/table"' in line:  # it subscribes to every channel at once
                        subscribed.set()

            assert client.stdout is not None
            threading.Thread(target=read, args=(client.stdout,), daemon=True).start()
            if not subscribed.wait(30):
                raise RuntimeError("the viewer did not subscribe within 30 s")
        with node:
            start, loop_start = time.process_time(), time.thread_time()
            relay(node, sender, drain, frames)
            loop = time.thread_time() - loop_start
            if view is not None:
                view.flush()  # shipping what is left is part of the cost
            spent = time.process_time() - start
        server = 0.0
        if view is not None:
            view.close()
            assert view.counters["sent"] + view.counters["throttled"] >= len(frames), view.counters
            server, view = view.server_cpu, None
        return spent / len(frames), loop / len(frames), server / len(frames)
    finally:
        if view is not None:
            view.close()
        if client is not None:
            assert client.stdin is not None
            client.stdin.close()
            client.wait(timeout=10)
        sender.shutdown()
        drain.shutdown()


@benchmark("live")
def relay_cpu() -> Iterator[Result]:
    """Best of five runs each, alternated, so both see the same machine."""
    if shutil.which("node") is None or not (_CLIENT.parent / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        print("live.relay_cpu: left out: needs node and tests/live/node_modules (make test installs them)",
              file=sys.stderr)
        return
    frames = _frames(_N)
    without, with_viewer = [], []
    for run in range(5):
        without.append(_relay_cpu(frames, run, viewer=False))
        with_viewer.append(_relay_cpu(frames, run, viewer=True))
    bare = min(p for p, _, _ in without) * 1e6
    yield Result("live.gateway process CPU/msg, --foxglove + 1 viewer", min(p for p, _, _ in with_viewer) * 1e6,
                 "us", "without --foxglove (goal <= 1.2x)", bare)
    yield Result("live.gateway loop CPU/msg, --foxglove + 1 viewer", min(t for _, t, _ in with_viewer) * 1e6, "us",
                 "without --foxglove", min(t for _, t, _ in without) * 1e6)
    yield Result("live.server process CPU/msg (its own process)", min(s for _, _, s in with_viewer) * 1e6, "us",
                 "the gateway process without --foxglove", bare)
