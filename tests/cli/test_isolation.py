"""No link can stall another: `vstig bridge` processes beside a radio nobody reads and a peer sending huge samples.

The healthy path is timed message by message (perf_counter is system-wide, so the
times taken in this process compare with each other): it must keep a p50 delay
under 50 ms and lose nothing, and the bridge's memory must stay bounded.
"""

from __future__ import annotations

import json
import os
import re
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from peers import Listener, PtyPeer, start_vstig, stop, wait_for
from ports import free_port

from vstig_hw import Message, Op, encode
from vstig_hw.auth import SwarmKeys
from vstig_hw.framing import make_serial_framing

RATE_HZ = 500
COUNT = 3000  # 6 s of traffic
PROBE_KEY = 32767
MASTER = bytes(range(0x40, 0x60))
COBS8 = make_serial_framing("cobs8")


def _frame(msg: Message, tagged: bool) -> bytes:
    """The cobs8 frame robot 7 sends: the message alone, or its record under the swarm's keys (SPEC.md 10.5)."""
    return COBS8.encode_tagged([SwarmKeys(MASTER).tag(msg, 0)])[0] if tagged else COBS8.encode(msg)[0]


def _fill(radio: PtyPeer) -> None:
    """Fill what the radio's pty buffers towards its far end, as a radio would that stopped reading long ago."""
    os.set_blocking(radio.slave, False)
    try:
        while True:
            os.write(radio.slave, bytes(4096))
    except BlockingIOError:
        pass


def _rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        return int(next(line.split()[1] for line in status if line.startswith("VmRSS:")))


def _counters(err: str, link: str) -> dict[str, int]:
    line = next(line for line in err.splitlines() if re.fullmatch(rf"{re.escape(link)}: (\w+=\d+ ?)+", line))
    return {name: int(n) for name, n in re.findall(r"(\w+)=(\d+)", line)}


def _paced(count: int, send: Callable[[int], object]) -> list[float]:
    """send(i) at start + i / RATE_HZ, sleeping between; the times sent."""
    sent = []
    start = time.perf_counter() + 0.05
    for i in range(count):
        pause = start + i / RATE_HZ - time.perf_counter()
        if pause > 0:
            time.sleep(pause)
        sent.append(time.perf_counter())
        send(i)
    return sent


def _send_paced(radio: PtyPeer, count: int, tagged: bool = False) -> list[float]:
    """Message i (key i, a new entry) written to the radio at start + i / RATE_HZ; the times written."""
    frames = [_frame(Message(Op.PUT, i, i, 1, 7), tagged) for i in range(count)]
    return _paced(count, lambda i: radio.write(frames[i]))


class ZenohBridge:
    """`vstig bridge` of a listening zenoh link and one cobs8 radio, read by a Listener, and a peer session."""

    def __init__(self) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.radio = PtyPeer()
        self.process = start_vstig("bridge", f"zenoh:lab?listen={self.endpoint}",
                                   f"serial:{self.radio.path}?framing=cobs8", "--robot-id", "200", "--no-refresh")
        self.out = Listener(self.radio)
        self.peer = _zenoh_peer(self.endpoint)

    def await_peer(self) -> None:
        """Until a probe the peer publishes comes out of the radio: the bridge is up and hears the peer."""
        stamp = iter(range(1, 60_000))
        wait_for(lambda: PROBE_KEY in self.out.arrived, 30,
                 step=lambda: (self.peer.put("vstig/lab/0/301",
                                             encode(Message(Op.PUT, PROBE_KEY, 1, next(stamp), 301))),
                               time.sleep(0.1)))

    def stop(self) -> str:
        """Close everything; the bridge's stderr (its exit status checked)."""
        self.peer.close()
        _out, err = stop(self.process)
        self.out.close()
        self.radio.close()
        assert self.process.returncode == 0, err
        return err


def _await_bridge(into: PtyPeer, out: Listener, tagged: bool = False) -> None:
    """Until a probe written on one radio comes out of the other: the bridge is up."""
    stamp = iter(range(1, 60_000))
    wait_for(lambda: PROBE_KEY in out.arrived, 30,
             step=lambda: (into.write(_frame(Message(Op.PUT, PROBE_KEY, 1, next(stamp), 7), tagged)),
                           time.sleep(0.1)))


def _delays(sent: list[float], out: Listener) -> list[float]:
    return sorted(out.arrived[i] - sent[i] for i in range(len(sent)) if i in out.arrived)


@pytest.mark.parametrize("auth", ["off", "require"])
def test_a_radio_nobody_reads_delays_no_other_link(auth: str, tmp_path: Path) -> None:
    """With auth=require every unit is a record (SPEC.md 10.5), and the bridge writes them as it writes untagged
    ones: straight to the radio, the rest of what it does not take to that link's bounded queue."""
    source, healthy, deaf = PtyPeer(), PtyPeer(), PtyPeer()
    _fill(deaf)
    names = [os.path.basename(radio.path) for radio in (source, healthy, deaf)]
    tagged = auth == "require"
    key_file = tmp_path / "swarm.key"
    key_file.write_text(MASTER.hex() + "\n", encoding="ascii")
    key_file.chmod(0o600)
    bridge = start_vstig("bridge", *(f"serial:{radio.path}?framing=cobs8&auth={auth}"
                                     for radio in (source, healthy, deaf)),
                         "--robot-id", "200", "--budget", "2000", "--no-refresh",
                         *(("--swarm-key", str(key_file)) if tagged else ()))
    echo = Listener(source)  # the source radio hears the gateway's re-broadcasts: it reads them
    out = Listener(healthy)
    try:
        _await_bridge(source, out, tagged)
        rss_before = _rss_kb(bridge.pid)
        sent = _send_paced(source, COUNT, tagged)
        wait_for(lambda: len(out.arrived) > COUNT, 10, step=lambda: time.sleep(0.1))
        rss_after = _rss_kb(bridge.pid)
    finally:
        _out, err = stop(bridge)
        echo.close()
        out.close()
        for radio in (source, healthy, deaf):
            radio.close()
    assert bridge.returncode == 0, err
    delays = _delays(sent, out)
    assert len(delays) == COUNT  # the healthy radio lost nothing
    assert statistics.median(delays) < 0.050, f"p50 {statistics.median(delays) * 1e3:.1f} ms"
    stuck = _counters(err, names[2])
    assert stuck.get("queued", 0) > 1000, stuck  # the deaf radio really stopped taking: its messages wait
    assert err.count(f"{names[2]}: the device does not take what we send") == 1  # logged once for the episode
    assert rss_after - rss_before < 20_000, (rss_before, rss_after)  # kB: the deaf radio's queue is bounded


def _zenoh_peer(endpoint: str) -> Any:
    import zenoh

    config = zenoh.Config()
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


HUGE_SAMPLES = 8


def test_huge_zenoh_samples_are_refused_unread_while_honest_samples_go_through() -> None:
    """A sample just above max_sample reaches the link and is refused unread (rx_oversize); a 4 MB one is dropped
    by Zenoh itself as it reassembles it (max_message_size: max_sample + 64 KiB), before a gateway could count
    it, and costs no memory (DECISIONS.md, "What a Zenoh peer can make a gateway hold")."""
    import zenoh

    bridge = ZenohBridge()
    flooder = _zenoh_peer(bridge.endpoint)  # beside the honest peer, one sending huge samples
    huge = encode(Message(Op.PUT, 1, 1, 1, 300)) * (4 * 1024 * 1024 // 8)  # 4 MB: 524,288 messages
    over = encode(Message(Op.PUT, 1, 1, 1, 300)) * (64 * 1024 // 8 + 1)  # one message above max_sample
    try:
        bridge.await_peer()
        rss_before = _rss_kb(bridge.process.pid)

        def flood() -> None:
            for _ in range(HUGE_SAMPLES):
                for payload in (huge, over):
                    flooder.put("vstig/lab/0/300", payload, congestion_control=zenoh.CongestionControl.BLOCK)
                time.sleep(0.3)

        flooding = threading.Thread(target=flood)
        flooding.start()
        count = 600  # 3 s at RATE_HZ, the huge samples among them
        sent = _paced(count, lambda i: bridge.peer.put("vstig/lab/0/301", encode(Message(Op.PUT, i, i, 1, 301))))
        flooding.join()
        wait_for(lambda: len(bridge.out.arrived) > count, 10, step=lambda: time.sleep(0.1))
        rss_after = _rss_kb(bridge.process.pid)
    finally:
        flooder.close()
        err = bridge.stop()
    delays = _delays(sent, bridge.out)
    assert len(delays) == count  # every honest message crossed
    assert statistics.median(delays) < 0.050, f"p50 {statistics.median(delays) * 1e3:.1f} ms"
    counters = _counters(err, "zenoh-lab")
    assert counters.get("rx_oversize") == HUGE_SAMPLES, err  # those just above: refused, none decoded
    assert counters["in"] < 2 * count, err  # nothing of the huge ones was decoded either (524,288 messages each)
    assert err.count("refused a 65544-byte sample") == 1
    # kB: Zenoh held ~24 MB of reassembly buffers for 4 MB samples before their size was bounded
    assert rss_after - rss_before < 15_000, (rss_before, rss_after)


FLOOD = """
import json, sys, time
import zenoh
from vstig_hw import Message, Op, encode
config = zenoh.Config()
config.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
config.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(config)
publisher = session.declare_publisher("vstig/lab/0/300", congestion_control=zenoh.CongestionControl.DROP)
# The same 64 entries again and again: the gateway decodes, judges and merges every one (the work a flood
# costs) and has nothing new to send, so the healthy radio's bandwidth stays the honest messages'.
payload = b"".join(encode(Message(Op.PUT, 20000 + k, 1, 1, 300)) for k in range(64))
end, sent = time.monotonic() + float(sys.argv[2]), 0
while time.monotonic() < end:  # unpaced: as fast as this process can publish
    publisher.put(payload)
    sent += 1
print(sent)
"""


def test_an_unpaced_zenoh_flood_does_not_starve_another_links_reads() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    source, healthy = PtyPeer(), PtyPeer()
    bridge = start_vstig("bridge", f"zenoh:lab?listen={endpoint}", *(f"serial:{radio.path}?framing=cobs8"
                                                                    for radio in (source, healthy)),
                         "--robot-id", "200", "--budget", "2000", "--no-refresh")
    echo, out = Listener(source), Listener(healthy)
    try:
        _await_bridge(source, out)
        flooder = subprocess.Popen([sys.executable, "-c", FLOOD, endpoint, "5"], stdout=subprocess.PIPE, text=True)
        time.sleep(1.0)  # the flood is under way
        sent = _send_paced(source, 1000)  # 2 s
        flooded, _ = flooder.communicate(timeout=30)
        wait_for(lambda: len(out.arrived) > 1000, 10, step=lambda: time.sleep(0.1))
    finally:
        _out, err = stop(bridge)
        echo.close()
        out.close()
        source.close()
        healthy.close()
    assert bridge.returncode == 0, err
    assert int(flooded) > 1000  # samples of 64 messages, unpaced
    assert _counters(err, "zenoh-lab")["rx"] > 1000, err  # the gateway did take the flood
    assert _counters(err, "engine")["same"] > 64_000, err  # and judged every message of it
    delays = _delays(sent, out)
    assert len(delays) == 1000
    assert statistics.median(delays) < 0.050, f"p50 {statistics.median(delays) * 1e3:.1f} ms"
