"""`vstig bridge` stopped while flooded (issue 38, item 1): every frame it read is handled or counted in the
counters it prints, whatever the moment of the stop. Real processes, real ptys (pyserial in the bridge)."""

from __future__ import annotations

import random
import re
import time

import pytest
from flood import FRAME, FloodedPty
from peers import start_vstig, stop, wait_for

pytestmark = pytest.mark.slow


def _printed(err: str, link: str) -> dict[str, int]:
    """The counters the bridge printed for `link` on exit (`name: key=value ...`)."""
    [line] = [line for line in err.splitlines() if line.startswith(f"{link}: ") and "rx_bytes=" in line]
    return {key: int(value) for key, value in re.findall(r"(\w+)=(\d+)", line)}


@pytest.mark.parametrize("mode", [["--raw"], ["--robot-id", "200", "--budget", "2000", "--no-refresh"]])
def test_a_flooded_bridge_stopped_at_random_moments_prints_every_frame_it_read(mode: list[str]) -> None:
    chance = random.Random(38)
    for _ in range(3):
        radios = [FloodedPty(7), FloodedPty(8)]
        try:
            bridge = start_vstig("bridge", *(f"serial:{radio.path}?framing=cobs8" for radio in radios), *mode)
            wait_for(lambda radios=radios: all(r.written > 20 * FRAME * 64 for r in radios), 30)  # read, under load
            time.sleep(chance.uniform(0.0, 0.5))
            _out, err = stop(bridge)
        finally:
            for radio in radios:
                radio.stop()
                radio.close()
        assert bridge.returncode == 0, err
        for radio in radios:
            link = radio.path.rsplit("/", 1)[-1]
            counters = _printed(err, link)
            assert counters["rx_bytes"] // FRAME == counters["in"] + counters.get("dropped_at_stop", 0), err
