"""`vstig put` and `vstig get` as subprocesses against a robot on a pty radio."""

from __future__ import annotations

import threading

from peers import PtyPeer, run_vstig, wait_for

from vstig_hw import Stigmergy
from vstig_hw.framing import make_serial_framing


class RadioRobot(threading.Thread):
    """A robot on the far end of a cobs8 radio: hears, answers, re-broadcasts, every few ms."""

    def __init__(self, robot_id: int) -> None:
        super().__init__(daemon=True)
        self.radio = PtyPeer()
        self.engine = Stigmergy(robot_id)
        self.framing = make_serial_framing("cobs8")
        self.running = True

    def run(self) -> None:
        while self.running:
            for msg in self.framing.feed(self.radio.read(0.005)):
                self.engine.receive(msg)
            for msg in self.engine.drain():
                for unit in self.framing.encode(msg):
                    self.radio.write(unit)

    def stop(self) -> None:
        self.running = False
        self.join(timeout=2)
        self.radio.close()


def test_get_prints_the_value_a_neighbour_holds_and_put_overrides_it() -> None:
    robot = RadioRobot(12)
    for _ in range(4):
        robot.engine.put(3, 500)  # the swarm's entry is at timestamp 4
    robot.engine.drain()
    robot.start()
    try:
        got = run_vstig("get", "3", "--on", f"serial:{robot.radio.path}", "--wait", "10")
        assert got.returncode == 0, got.stderr
        assert got.stdout.strip() == "key=3 value=500 timestamp=4 robot=12"
        put = run_vstig("put", "3", "777", "--on", f"serial:{robot.radio.path}", "--robot-id", "99", "--learn", "5")
        assert put.returncode == 0, put.stderr
        assert "timestamp=5" in put.stdout  # it learned the swarm's timestamp first, so its write is newer
        wait_for(lambda: robot.engine.entry(3) == (777, 5, 99), 10)
    finally:
        robot.stop()


def test_get_says_when_no_neighbour_answers() -> None:
    silent = PtyPeer()
    try:
        got = run_vstig("get", "8", "--on", f"serial:{silent.path}", "--wait", "0.5")
    finally:
        silent.close()
    assert got.returncode == 1
    assert "no neighbour" in got.stderr and "key 8" in got.stderr and "Traceback" not in got.stderr
