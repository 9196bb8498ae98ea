"""Many PCs on one clock: two PCs 250 ms apart (clock_ahead.c sets one's wall clock ahead on purpose), each in its own
network namespace, record the same swarm over Zenoh; their captures carry the clock offset they measured by round
trips, and `analyze` merges them on one time base within 2 ms of the truth.

PC A runs a bridge with a robot on a pty radio and a recorder; PC B, a recorder whose clock is 250 ms ahead.
Both recorders hear each sample the bridge publishes within a fraction of a millisecond of each other, so once
B's times are put on A's clock, the same sample must carry the same time in both captures.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from netns import Lan, netns_unavailable
from peers import STARTED, VSTIG, run_vstig, stop, wait_for
from ports import free_port
from required import require_tool
from robots import PtyRobot

from vstig_hw.capture.zenoh_log import read_zenoh_capture

pytestmark = pytest.mark.slow

AHEAD_S = 0.25  # PC B's clock, set ahead of A's by libfaketime
WITHIN_S = 0.002


def _clock_ahead(folder: Path) -> str:
    """The LD_PRELOAD library that runs a process's wall clock ahead (clock_ahead.c), built here with gcc."""
    gcc = require_tool("gcc")
    library = folder / "clock_ahead.so"
    subprocess.run([gcc, "-shared", "-fPIC", "-O2", "-o", str(library), str(Path(__file__).with_name("clock_ahead.c")),
                    "-ldl"], check=True, capture_output=True, timeout=120)
    return str(library)


@pytest.fixture
def lan() -> Iterator[Lan | None]:
    if netns_unavailable():
        if os.environ.get("VSTIG_REQUIRE_PEERS"):
            pytest.fail(str(netns_unavailable()))
        yield None  # both PCs on loopback: the clocks are still apart
        return
    made = Lan(2)
    try:
        yield made
    finally:
        made.close()


def test_captures_from_two_pcs_250_ms_apart_merge_within_2_ms_of_the_truth(tmp_path: Path, lan: Lan | None) -> None:
    library = _clock_ahead(tmp_path)
    host_a = lan.address(0) if lan else "127.0.0.1"
    port = 7447 if lan else free_port()
    on = [lan.command(n) if lan else [] for n in range(2)]
    robot = PtyRobot(5)
    swarm = f"zenoh:lab?listen=tcp/{host_a}:{port}"
    joins = f"zenoh:lab?connect=tcp/{host_a}:{port}"
    a_cap, b_cap = tmp_path / "pc-a.cap", tmp_path / "pc-b.cap"
    ahead = {**os.environ, "LD_PRELOAD": library, "CLOCK_AHEAD_NS": str(int(AHEAD_S * 1e9))}

    def start(argv: list[str], env: dict[str, str] | None = None) -> subprocess.Popen[str]:
        process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
        STARTED.append(process)
        return process

    bridge = start([*on[0], VSTIG, "bridge", robot.spec, swarm, "--robot-id", "200"])
    recorder_a = start([*on[0], VSTIG, "record", joins, "-o", str(a_cap)])
    metrics = f"127.0.0.1:{free_port()}"  # B's recorder also shows its offsets to Prometheus
    recorder_b = start([*on[1], VSTIG, "record", joins, "-o", str(b_cap), "--metrics", metrics], env=ahead)
    writing = threading.Event()

    def robot_writes() -> None:  # a new value every 50 ms: samples for both recorders to hear
        value = 0
        while not writing.is_set():
            value += 1
            robot.put(1, value)
            time.sleep(0.05)

    writer = threading.Thread(target=robot_writes, daemon=True)
    try:
        wait_for(lambda: a_cap.exists() and b_cap.exists(), 60)
        writer.start()
        wait_for(lambda: "clock-offset" in a_cap.read_text() and "clock-offset" in b_cap.read_text(), 60)
        time.sleep(6)  # a few more round trips (one every 2 s) and ~120 samples
        scrape = "import sys, urllib.request; print(urllib.request.urlopen(sys.argv[1], timeout=5).read().decode())"
        page = subprocess.run([*on[1], sys.executable, "-c", scrape, f"http://{metrics}/metrics"],
                              capture_output=True, text=True, timeout=60, check=True).stdout
    finally:
        writing.set()
        for process in (recorder_a, recorder_b, bridge):
            stop(process, timeout=20)
        robot.close()
    assert recorder_a.returncode == 0 and recorder_b.returncode == 0

    # Open TCP links: no certificate proves who answered, so the offsets are used only when trusted outright.
    untrusted = run_vstig("analyze", str(a_cap), str(b_cap), "--json")
    assert untrusted.returncode == 0 and json.loads(untrusted.stdout)["capture"]["clocks"][1] is None
    done = run_vstig("analyze", str(a_cap), str(b_cap), "--json", "--trust-clock-notes")
    assert done.returncode == 0, done.stderr
    shift = json.loads(done.stdout)["capture"]["clocks"][1]
    assert abs(shift["shift_s"] - AHEAD_S) < WITHIN_S, shift  # B's clock is 250 ms ahead: taken off its times
    assert shift["error_s"] < WITHIN_S
    assert f"pc-b.cap: on {a_cap}'s clock: -2" in done.stderr  # said: about -250 ms, with its bound

    gauges = [float(v) for v in re.findall(r"^vstig_clock_offset_seconds\{peer=\"\w+\",proved_by=\"\"\} (\S+)$", page,
                                           re.M)]
    assert any(abs(gauge + AHEAD_S) < WITHIN_S for gauge in gauges), page  # the bridge's clock, 250 ms behind B's

    heard_a, heard_b = _once(a_cap, 0.0), _once(b_cap, shift["shift_s"])
    both = heard_a.keys() & heard_b.keys()
    assert len(both) >= 50
    apart = sorted(abs(heard_a[sample] - heard_b[sample]) for sample in both)
    assert apart[len(apart) // 2] < WITHIN_S, apart[-5:]  # the same sample at the same time, on one clock
    # each recorder's own delivery jitter is in these gaps too: a loaded PC delays some past 2 ms
    assert sum(gap < WITHIN_S for gap in apart) >= 0.75 * len(apart), apart[-10:]
    raw = sorted(abs(heard_a[s] - (heard_b[s] + shift["shift_s"])) for s in both)
    assert raw[len(raw) // 2] > AHEAD_S - WITHIN_S  # on their own clocks they were a quarter second apart


def _once(capture: Path, shift: float) -> dict[tuple[str, bytes], float]:
    """Each sample heard exactly once in the capture (a payload sent twice cannot be told apart), at its time
    less `shift`."""
    times: dict[tuple[str, bytes], list[float]] = {}
    for record in read_zenoh_capture(str(capture)):
        times.setdefault((record.unit.key, record.unit.payload), []).append(record.t - shift)
    return {sample: heard[0] for sample, heard in times.items() if len(heard) == 1}
