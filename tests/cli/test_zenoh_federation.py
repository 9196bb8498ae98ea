"""Three `vstig bridge` processes joined only by zenoh links, each with its own robots on real radios.

As root each gateway runs in its own network namespace, so the samples cross
real interfaces (veth pairs on a bridge), and the partition test cuts and heals
a gateway's cable. Elsewhere the gateways meet on loopback and the partition
test skips (VSTIG_REQUIRE_PEERS=1 makes that a failure).
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from netns import Lan, netns_unavailable
from peers import VSTIG, wait_for
from ports import free_port
from robots import CanRobot, PtyRobot, Robot

pytestmark = pytest.mark.slow

SWARM = "lab"
STEP = 0.1  # the paper's control step
# A short lease, so a cut cable is noticed in about 2 s instead of Zenoh's default 10 s; passed through config=.
CONFIG = "{ transport: { link: { tx: { lease: 2000, keep_alive: 4 } } } }\n"


class Gateway:
    """One `vstig bridge` process: its robots' radios plus one zenoh link; stderr collected as it comes."""

    def __init__(self, index: int, robots: list[Robot], prefix: list[str], zenoh_spec: str) -> None:
        self.index = index
        self.robots = robots
        self.argv = [*prefix, VSTIG, "bridge", *(r.spec for r in robots), zenoh_spec,
                     "--robot-id", str(200 + index), "--larger-value-wins"]
        self.log: list[str] = []
        self.process: subprocess.Popen[str] | None = None
        self.up = False  # should be running (a gateway the test stopped is not a crash)

    def start(self) -> None:
        self.log.clear()
        self.up = True
        self.process = subprocess.Popen(self.argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        stream = self.process.stderr
        threading.Thread(target=lambda: self.log.extend(stream or ()), daemon=True).start()

    def said(self, words: str) -> bool:
        return any(words in line for line in self.log)

    def stop(self, sig: int = signal.SIGTERM) -> int:
        assert self.process is not None
        self.up = False
        if self.process.poll() is None:
            self.process.send_signal(sig)
        code = self.process.wait(timeout=20)
        time.sleep(0.1)  # the pump thread reads the last lines
        return code


class Federation:
    def __init__(self, tmp_path: Path, lan: Lan | None, robots: list[list[Robot]]) -> None:
        config = tmp_path / "lab.json5"
        config.write_text(CONFIG)
        hosts = [lan.address(n) if lan else "127.0.0.1" for n in range(len(robots))]
        ports = [7447 if lan else free_port() for _ in robots]
        self.gateways = []
        for n, own in enumerate(robots):
            spec = f"zenoh:{SWARM}?listen=tcp/{hosts[n]}:{ports[n]}&config={config}"
            if n:
                spec += f"&connect=tcp/{hosts[0]}:{ports[0]}"
            self.gateways.append(Gateway(n, own, lan.command(n) if lan else [], spec))
        self.robots = [robot for own in robots for robot in own]
        self.on_lan = lan is not None

    def step(self) -> None:
        for robot in self.robots:
            robot.step()
        time.sleep(STEP)
        for gateway in self.gateways:
            died = gateway.up and gateway.process is not None and gateway.process.poll() is not None
            assert not died, f"gateway {gateway.index} died: {''.join(gateway.log)}"

    def run_until(self, done: Callable[[], bool], deadline: float = 60.0) -> None:
        wait_for(done, deadline, step=self.step)

    def agree(self, key: int, value: int, robots: list[Robot] | None = None) -> Callable[[], bool]:
        return lambda: all(robot.value(key) == value for robot in robots or self.robots)


@pytest.fixture
def lan_or_loopback() -> Iterator[Lan | None]:
    if netns_unavailable():
        yield None
        return
    lan = Lan(3)
    try:
        yield lan
    finally:
        lan.close()


@pytest.fixture
def lan() -> Iterator[Lan]:
    reason = netns_unavailable()
    if reason:
        if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
            pytest.fail(f"VSTIG_REQUIRE_PEERS=1 but {reason}")
        pytest.skip(f"the partition test cuts network namespaces' cables: {reason}")
    made = Lan(3)
    try:
        yield made
    finally:
        made.close()


def _federation(tmp_path: Path, lan: Lan | None) -> Iterator[Federation]:
    robots: list[list[Robot]] = [[PtyRobot(31)], [PtyRobot(32)], [PtyRobot(33), CanRobot(240)]]
    federation = Federation(tmp_path, lan, robots)
    try:
        for gateway in federation.gateways:
            gateway.start()
        for robot in federation.robots:
            robot.put(1, robot.id)  # the paper's task: every robot puts its id; the larger value wins
        yield federation
    finally:
        for gateway in federation.gateways:
            if gateway.process is not None and gateway.process.poll() is None:
                gateway.stop(signal.SIGKILL)
        for robot in federation.robots:
            robot.close()


@pytest.fixture
def federation(tmp_path: Path, lan_or_loopback: Lan | None) -> Iterator[Federation]:
    yield from _federation(tmp_path, lan_or_loopback)


@pytest.fixture
def partitioned(tmp_path: Path, lan: Lan) -> Iterator[tuple[Federation, Lan]]:
    for federation in _federation(tmp_path, lan):
        yield federation, lan


def test_three_gateways_converge_and_a_restarted_one_catches_up(federation: Federation) -> None:
    federation.run_until(federation.agree(1, 240))  # the CAN robot's id, across two zenoh hops for some
    first, middle, _ = federation.gateways

    middle.stop(signal.SIGKILL)  # no goodbye: its robot keeps running, its engine's memory is gone
    alone, elsewhere = middle.robots[0], first.robots[0]
    others = [r for r in federation.robots if r is not alone]
    for robot in federation.robots:
        robot.watch |= {4, 5}
    alone.put(5, 555)  # written in the dark: its gateway is down
    elsewhere.put(4, 444)
    federation.run_until(federation.agree(4, 444, others))
    assert alone.value(4) is None and all(r.value(5) is None for r in others)  # really cut off

    middle.start()  # a fresh engine: its robot's GETs hand it key 5; the others' round-robin GETs, key 4
    federation.run_until(lambda: federation.agree(5, 555)() and federation.agree(4, 444)())
    assert federation.agree(1, 240)()  # nothing lost anywhere

    for gateway in federation.gateways:
        assert gateway.stop() == 0, "".join(gateway.log)
        # Listening on the LAN with no authentication is worth a warning; on loopback it is not.
        assert gateway.said("WARNING: this gateway listens on tcp/10.77.0.") == federation.on_lan
        counters = next(line for line in gateway.log if line.startswith("zenoh-lab: ") and "in=" in line)
        assert "out=" in counters and "tx=" in counters and "rx=" in counters
        assert not any("Traceback" in line for line in gateway.log)


def test_a_partition_heals_and_both_sides_converge(partitioned: tuple[Federation, Lan]) -> None:
    federation, lan = partitioned
    federation.run_until(federation.agree(1, 240))
    side_a = federation.gateways[0].robots + federation.gateways[1].robots
    side_c = federation.gateways[2].robots
    for robot in federation.robots:
        robot.watch |= {2, 3}

    lan.cut(2)
    cut_off = federation.gateways[2]
    federation.run_until(lambda: cut_off.said("lost every Zenoh peer"), 30)
    side_a[0].put(2, 111)  # a write on each side under the same key: both at timestamp 1, a conflict later
    side_c[0].put(2, 222)
    side_a[1].put(3, 333)  # and one the other side must learn
    federation.run_until(lambda: federation.agree(2, 111, side_a)() and federation.agree(3, 333, side_a)(), 30)
    assert all(robot.value(3) is None and robot.value(2) == 222 for robot in side_c)  # really cut off

    lan.heal(2)
    federation.run_until(lambda: federation.agree(2, 222)() and federation.agree(3, 333)(), 60)  # larger value wins
    federation.run_until(lambda: cut_off.said("Zenoh peers reachable again"), 10)  # checked once a second
    assert cut_off.stop() == 0
    summary = next(line for line in cut_off.log if line.startswith("zenoh-lab: ") and "in=" in line)
    assert "lost=1" in summary and "reconnects=1" in summary
