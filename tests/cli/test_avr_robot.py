"""A libvstig robot on a simulated ATmega328P (simavr), its UART a pty speaking cobs8, joins `vstig bridge` beside a
pty robot and a CAN robot (python-can's real slcan driver in the bridge), and the three agree.

The firmware runs the paper's program (firmware_spec/libvstig/examples/avr_robot.c): it writes its id under key 1,
the larger value wins, and it reports the value it holds for key 1 under key 0x100 + its id. So the other robots
see the AVR's own engine converge, not only the bridge's.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from avr_robot import AvrRobot, build
from peers import start_vstig, stop, wait_for
from robots import CanRobot, PtyRobot, Robot

AVR_ID = 3
REPORT = 0x100 + AVR_ID  # where the AVR robot reports what it holds for key 1


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return build(tmp_path_factory.mktemp("avr"))


@pytest.fixture
def swarm(built: tuple[Path, Path]) -> Iterator[tuple[AvrRobot, list[Robot]]]:
    avr = AvrRobot(built, AVR_ID)
    others: list[Robot] = [PtyRobot(11, watch=(1, REPORT)), CanRobot(21, watch=(1, REPORT))]
    try:
        yield avr, others
    finally:
        for robot in others:
            robot.close()
        assert "crashed" not in avr.close()


def _agree(robots: list[Robot], key: int, value: int) -> bool:
    return all(robot.value(key) == value for robot in robots)


@pytest.mark.slow  # python-can's slcan driver sleeps 2 s after opening its port
def test_an_avr_robot_converges_with_pty_and_can_robots_through_the_bridge(
        swarm: tuple[AvrRobot, list[Robot]]) -> None:
    avr, others = swarm
    for robot in others:
        robot.put(1, robot.id)
    bridge = start_vstig("bridge", avr.spec, *(robot.spec for robot in others), "--robot-id", "200",
                         "--larger-value-wins")
    try:
        def step() -> None:
            for robot in others:
                robot.step()
            if bridge.poll() is not None:
                raise AssertionError(f"the bridge ended: {bridge.communicate()[1][-2000:]}")

        # every robot holds the CAN robot's 21, and the AVR says it holds it too
        wait_for(lambda: _agree(others, 1, 21) and _agree(others, REPORT, 21), 60, step=step)
        others[1].put(1, 900)  # a later write from the CAN bus reaches the AVR, which reports it back
        wait_for(lambda: _agree(others, 1, 900) and _agree(others, REPORT, 900), 60, step=step)
        assert all(robot.engine.entry(REPORT).robot == AVR_ID for robot in others)  # type: ignore[union-attr]
    finally:
        _out, err = stop(bridge)
    assert bridge.returncode == 0, err
