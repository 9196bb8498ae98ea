"""`vstig bridge` and `vstig record` stopped while flooded (issue 38, item 1): every frame they read is handled
(relayed, recorded) or counted in the counters they print, whatever the moment of the stop. Real processes, real
ptys (pyserial in the command)."""

from __future__ import annotations

import random
import re
import time
from pathlib import Path

import pytest
from flooded_pty import FRAME, FloodedPty
from peers import has_open, start_vstig, stop, wait_for

from vstig_hw.framing import make_serial_framing

pytestmark = pytest.mark.slow

READING = 256 * 64 * FRAME  # bytes a radio wrote once the command reads it: beyond what a pty holds unread


def _reading(command: object, radios: list[FloodedPty]) -> None:
    """Wait until `command` has every radio open and has read well past what a pty buffers by itself."""
    pid = command.pid  # type: ignore[attr-defined]
    try:
        wait_for(lambda: all(has_open(pid, radio.path) and radio.written > READING for radio in radios), 60)
    except AssertionError:
        said = command.communicate(timeout=5)[1] if command.poll() is not None else ""  # type: ignore[attr-defined]
        raise AssertionError(f"not reading after 60 s: open {[has_open(pid, r.path) for r in radios]}, written "
                             f"{[r.written for r in radios]}, said {said!r}") from None


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
            _reading(bridge, radios)
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


def test_a_flooded_recording_stopped_holds_every_frame_it_read_or_counts_it(tmp_path: Path) -> None:
    """The capture holds every unit handed over before the stop (the file closes after the node handed them
    on), and the printed counters account for every frame the device read."""
    radio = FloodedPty(7)
    capture = tmp_path / "flood.cap"
    try:
        recorder = start_vstig("record", f"serial:{radio.path}?framing=cobs8", "-o", str(capture))
        _reading(recorder, [radio])
        time.sleep(random.Random(381).uniform(0.0, 0.5))
        _out, err = stop(recorder)
    finally:
        radio.stop()
        radio.close()
    assert recorder.returncode == 0, err
    counters = _printed(err, radio.path.rsplit("/", 1)[-1])
    assert counters["rx_bytes"] // FRAME == counters["in"] + counters.get("dropped_at_stop", 0), err
    recorded = bytes.fromhex("".join(line.split()[-1] for line in capture.read_text().splitlines() if " rx " in line))
    assert len(make_serial_framing("cobs8").feed(recorded)) == counters["in"]  # every message handled is in it
    if not counters.get("dropped_at_stop"):
        assert len(recorded) == counters["rx_bytes"]  # every byte read
