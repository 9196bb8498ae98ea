"""What a Zenoh peer can make a `vstig bridge` hold: one huge sample, and peers that flood and leave.

A real bridge process (a pty robot and a zenoh link on 127.0.0.1) and stock zenoh-python peers in processes of
their own, with Zenoh's defaults (1 GiB messages, shared memory on). The bridge's memory is read from
/proc/PID/status (VmRSS now, VmHWM its peak), and after each attack an honest peer's write still reaches the
robot.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from peers import start_vstig, stop, wait_for
from ports import free_port
from robots import PtyRobot

from vstig_hw.links import parse
from vstig_hw.wire import Message, Op

pytestmark = pytest.mark.slow

ATTACKER = str(Path(__file__).with_name("zenoh_attacker.py"))
MiB = 1 << 20


def _memory(pid: int) -> tuple[float, float]:
    """(resident MB now, peak resident MB) of process `pid`."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines())
    return int(fields["VmRSS"].split()[0]) / 1024, int(fields["VmHWM"].split()[0]) / 1024


class Bridge:
    """`vstig bridge` with one pty robot and a zenoh link listening on a loopback port."""

    def __init__(self) -> None:
        self.robot = PtyRobot(1, watch=(5,))
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.process = start_vstig("bridge", self.robot.spec, f"zenoh:lab?listen={self.endpoint}", "--robot-id",
                                   "201")
        self.log: list[str] = []
        stream = self.process.stderr
        threading.Thread(target=lambda: self.log.extend(stream or ()), daemon=True).start()
        wait_for(lambda: any("listening on" in line for line in self.log), 30)

    @property
    def memory(self) -> tuple[float, float]:
        return _memory(self.process.pid)

    def attack(self, *args: str) -> None:
        done = subprocess.run([sys.executable, ATTACKER, args[0], self.endpoint, *args[1:]], capture_output=True,
                              text=True, timeout=120, check=False)
        assert done.returncode == 0 and done.stdout.startswith("sent "), done.stderr[-2000:]

    def honest_write_arrives(self, value: int) -> bool:
        """An honest gateway's PUT reaches the robot behind the bridge."""
        honest = parse(f"zenoh:lab?connect={self.endpoint}").build(robot_id=202)
        honest.open()
        try:
            end = time.monotonic() + 20
            while time.monotonic() < end:
                honest.send(Message(Op.PUT, 5, value, value, 202))
                self.robot.step()
                if self.robot.value(5) == value:
                    return True
                time.sleep(0.1)
            return False
        finally:
            honest.close()


@pytest.fixture
def bridge() -> Iterator[Bridge]:
    gateway = Bridge()
    try:
        yield gateway
    finally:
        stop(gateway.process)
        gateway.robot.close()


def test_one_900_mib_sample_does_not_take_the_bridges_memory(bridge: Bridge) -> None:
    before, _ = bridge.memory
    bridge.attack("huge", str(900 * MiB))
    after, peak = bridge.memory
    assert peak <= 250, f"peak {peak:.0f} MB while a peer sent one 900 MiB sample"  # was 958 MB
    assert after <= before + 30, f"{before:.0f} MB before, {after:.0f} MB after the peer left"
    assert bridge.honest_write_arrives(77)


def test_peers_that_flood_and_leave_five_times_leave_the_bridge_near_where_it_was(bridge: Bridge) -> None:
    before, _ = bridge.memory
    grown = []
    for _ in range(5):  # 64 KiB samples of valid messages, Zenoh's largest batch: the worst of the floods tried
        bridge.attack("flood", str(64 * 1024 - 8), "2")
        time.sleep(1)
        grown.append(round(bridge.memory[0] - before))
    assert grown[-1] < 40, f"RSS grew by {grown} MB after each of five floods"  # was +117-126 MB
    assert bridge.honest_write_arrives(78)
