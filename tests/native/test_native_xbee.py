"""The compiled delivery reading an XBee module itself (Path.pump: libvstig cuts the module's bytes into frames)
against the pure-Python Node reading them through its transport: real ptys to emulated modules (tests/xbee), the
same hostile bytes in the same bursts to each, with pauses that end frames still arriving. Both must count the same
drops, reports and units, and hand the guard the same messages from the same senders (the 64-bit sources).
"""

from __future__ import annotations

import os
import random
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType

import pytest
from traffic import xbee_stream

from vstig_hw import Message
from vstig_hw.counters import Counters
from vstig_hw.gateway import assembly as assembly_module
from vstig_hw.gateway.guard import Guard
from vstig_hw.gateway.node import Mode, Node
from vstig_hw.links.serial import serial_link

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "xbee"))
from xbee_network import Module, XBeeNetwork

QUIET_PAUSE = 0.25  # > the transport's quiet time: a frame still arriving is cut short


class RecordingGuard(Guard):
    """A guard that passes everything (a rate no link reaches keeps it Python on either path) and notes what it was
    asked: the sender and the messages of each unit."""

    def __init__(self) -> None:
        super().__init__(max_jump=None, rate=1e9)
        self.asked: list[tuple[int | None, list[Message]]] = []

    def filter(self, link: str, sender: int | None, messages: Sequence[Message], t: float, counters: Counters,
               source: str | None = None) -> list[Message]:
        self.asked.append((sender, list(messages)))
        return super().filter(link, sender, messages, t, counters, source)


def _node(module: Module, sink: str, compiled: bool) -> tuple[Node, RecordingGuard]:
    """A raw relay from the module to a pty nobody reads: nothing is written to the module, so all it reports is
    what the test injects."""
    guard = RecordingGuard()
    links = [serial_link(module.path, "xbee-api2" if module.api == 2 else "xbee", 230400, name="radio"),
             serial_link(sink, "cobs8", 115200, name="sink")]
    with pytest.MonkeyPatch.context() as patch:
        if not compiled:
            patch.setattr(assembly_module, "compiled_for", lambda relays, links: None)
        node = Node(links, 9, mode=Mode.RAW, guard=guard)
    assert (node._delivery.path is not None) == compiled
    return node, guard


@pytest.fixture
def sinks() -> Iterator[list[str]]:
    pairs = [os.openpty() for _ in range(2)]
    yield [os.ttyname(slave) for _master, slave in pairs]
    for pair in pairs:
        for fd in pair:
            os.close(fd)


@pytest.fixture
def network() -> Iterator[XBeeNetwork]:
    with XBeeNetwork() as net:
        yield net


def _received(node: Node) -> dict[str, int]:
    """What the link counted of what it heard (the module's own reports, drops, units, bytes, messages)."""
    stats = node.links[0].stats()
    return {name: n for name, n in stats.items() if n and not name.startswith(("tx", "out"))} | \
        {name: n for name, n in stats.items() if n and name.startswith("tx_") and name not in ("tx_bytes",)}


@pytest.mark.parametrize("api", [1, 2])
def test_the_compiled_xbee_read_equals_the_transports(compiled: ModuleType, network: XBeeNetwork, sinks: list[str],
                                                      api: int) -> None:
    rng = random.Random(api)
    modules = [network.module(0x0013A20040000001 + i, api=api) for i in range(2)]
    nodes = [_node(module, sink, compiled=i == 1) for i, (module, sink) in enumerate(zip(modules, sinks, strict=True))]
    try:
        for node, _guard in nodes:
            node.open()
        deadline = time.monotonic() + 10
        while not all(node.links[0].transport.connected for node, _ in nodes):  # the modules answered at open
            assert time.monotonic() < deadline, "a node did not open its module"
            time.sleep(0.01)
        assert nodes[1][0]._delivery.path is not None and nodes[1][0]._delivery.path.pumps(0)  # read in C
        sent = 0
        for _ in range(12):
            stream = xbee_stream(rng, api == 2, frames=6)
            at = 0
            while at < len(stream):  # bursts of at most 1 kB, some ending inside a frame
                burst = stream[at:at + rng.randrange(1, 1024)]
                at += len(burst)
                for module in modules:
                    module.inject(burst)
                sent += len(burst)
                deadline = time.monotonic() + 10
                while any(node.links[0].transport.counters["rx_bytes"] < sent for node, _ in nodes):
                    assert time.monotonic() < deadline, "a node did not read what its module sent"
                    time.sleep(0.005)
                if rng.random() < 0.3:
                    time.sleep(QUIET_PAUSE)
        time.sleep(QUIET_PAUSE)
        (pure, pure_guard), (fast, fast_guard) = nodes
        assert _received(fast) == _received(pure)
        assert fast_guard.asked == pure_guard.asked
        assert any(sender is not None for sender, _ in pure_guard.asked)
        assert {name for name in _received(pure) if name.startswith("drop_")} >= {"drop_noise", "drop_checksum",
                                                                                  "drop_truncated", "drop_bad_length"}
    finally:
        for node, _guard in nodes:
            node.close()
