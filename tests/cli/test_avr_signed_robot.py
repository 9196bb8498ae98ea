"""A libvstig robot on a simulated ATmega328P (simavr) that tags its writes with its own key (SPEC.md section 10),
and a Python robot that does too, both on cobs8 pty radios with auth=require at a `vstig bridge --swarm-key`: they
agree on the paper's program, the AVR's report proven by its own tag; what neither could prove (their relays of
each other's entries, untagged: neither holds the other's key) is refused at the bridge, never the AVR's own."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from avr_robot import AvrRobot, build
from peers import VSTIG, start_vstig, stop, wait_for
from robots import PtyRobot

from vstig_hw.auth import SwarmKeys, Tagged, entry_tag, robot_key
from vstig_hw.wire import Message

AVR_ID, PY_ID = 3, 11
REPORT = 0x100 + AVR_ID  # where the AVR robot reports what it holds for key 1
MASTER = bytes(range(0x40, 0x60))


class SignedPtyRobot(PtyRobot):
    """A Python robot holding only its own key: its own entries go out as records, others' as they are."""

    def __init__(self, robot_id: int, watch: tuple[int, ...]) -> None:
        super().__init__(robot_id, watch)
        self.key = robot_key(MASTER, robot_id)
        self.records: list[Tagged] = []  # what it heard tagged

    def _heard(self) -> list[Message]:
        heard = self.framing.feed_tagged(self.radio.read(0))
        self.records += [record for _, record in heard if record is not None]
        return [msg for msg, _ in heard]

    def _send(self, messages: list[Message]) -> None:
        own = [Tagged(msg, 0, entry_tag(self.key, 0, msg, 0)) for msg in messages if msg.robot == self.id]
        others = [msg for msg in messages if msg.robot != self.id]
        data = b"".join(self.framing.encode_tagged(own) + self.framing.encode_batch(others))
        if data:
            self.radio.write(data)


@pytest.fixture(scope="module")
def keys(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """(the swarm key file, the signed firmware, the board)."""
    folder = tmp_path_factory.mktemp("avr-signed")
    swarm_key = folder / "swarm.key"
    swarm_key.write_text(MASTER.hex() + "\n", encoding="ascii")
    swarm_key.chmod(0o600)
    header = folder / "robot_key.h"
    done = subprocess.run([VSTIG, "keys", "--swarm-key", str(swarm_key), str(AVR_ID), "--format", "c"],
                          capture_output=True, text=True, timeout=60, check=False, env=None)
    assert done.returncode == 0, done.stderr
    header.write_text(done.stdout, encoding="ascii")
    firmware, board = build(folder, robot_key=header)
    return swarm_key, firmware, board


@pytest.fixture
def swarm(keys: tuple[Path, Path, Path]) -> Iterator[tuple[AvrRobot, SignedPtyRobot, Path]]:
    swarm_key, firmware, board = keys
    avr = AvrRobot((firmware, board), AVR_ID)
    robot = SignedPtyRobot(PY_ID, watch=(1, REPORT))
    try:
        yield avr, robot, swarm_key
    finally:
        robot.close()
        assert "crashed" not in avr.close()


def test_a_signing_avr_robot_converges_with_a_signing_python_robot_through_a_bridge_that_requires_tags(
        swarm: tuple[AvrRobot, SignedPtyRobot, Path]) -> None:
    avr, robot, swarm_key = swarm
    robot.put(1, PY_ID)
    bridge = start_vstig("bridge", f"{avr.spec}&auth=require", f"{robot.spec}&auth=require", "--robot-id", "200",
                         "--larger-value-wins", "--swarm-key", str(swarm_key))
    try:
        def step() -> None:
            robot.step()
            if bridge.poll() is not None:
                raise AssertionError(f"the bridge ended: {bridge.communicate()[1][-2000:]}")

        # the Python robot holds its own 11 (larger than the AVR's 3), and the AVR says, tagged, that it holds it
        wait_for(lambda: robot.value(1) == PY_ID and robot.value(REPORT) == PY_ID, 60, step=step)
    finally:
        _out, err = stop(bridge)
    assert bridge.returncode == 0, err
    report = [record for record in robot.records if record.message.key == REPORT]
    assert report and all(record.message.robot == AVR_ID for record in report), robot.records
    assert all(SwarmKeys(MASTER).verify(record) for record in report)  # the AVR's own tag, relayed as made
    avr_link = next(line for line in err.splitlines() if line.startswith(Path(avr.path).name + ": "))
    assert "drop_bad_tag" not in avr_link, err  # every tag the AVR made checks out
    print(f"bridge: {err.strip()}", file=sys.stderr)
