"""`vstig analyze` on a capture of a real bridged experiment agrees with the robots' own logs.

Four CAN robots (real engines, run by this test on a lossy bus it plays) and one
robot on a cobs8 pty radio; `vstig bridge` joins the two media through python-can's
slcan driver, and `vstig record` captures the bus through a second slcan adapter
that hears every frame. The radio robot writes once; each CAN robot logs the
control step at which its get first returned the value. analyze's convergence must
end within one control step of the last robot's log entry.
"""

from __future__ import annotations

import json
import random
import time
from pathlib import Path

import can
import pytest
from peers import PtyPeer, SlcanAdapter, run_vstig, start_vstig, stop, wait_for

from vstig_hw import Message, Stigmergy, encode
from vstig_hw.framing import make_serial_framing
from vstig_hw.wire import decode

pytestmark = pytest.mark.slow  # python-can's slcan driver sleeps 2 s after opening its port

STEP = 0.1  # the control step, seconds
KEY, VALUE = 1, 4040
CAN_ROBOTS = (1, 2, 3, 4)
RADIO_ROBOT = 40
BRIDGE = 200
DROP = 0.5  # each CAN robot misses each frame with this probability


def _frame(robot: int, msg: Message) -> can.Message:
    return can.Message(arbitration_id=0x600 | int(msg.op) << 8 | robot, data=encode(msg), is_extended_id=False)


def test_analyze_matches_the_robots_logs_within_one_step(tmp_path: Path) -> None:
    bus, listener, radio = SlcanAdapter(), SlcanAdapter(), PtyPeer()
    capture = tmp_path / "experiment.log"
    bridge = start_vstig("bridge", f"can:slcan:{bus.path}", f"serial:{radio.path}?framing=cobs8",
                         "--robot-id", str(BRIDGE))
    recorder = start_vstig("record", f"can:slcan:{listener.path}", "-o", str(capture))
    robots = {robot: Stigmergy(robot) for robot in CAN_ROBOTS}
    radio_robot, cobs8 = Stigmergy(RADIO_ROBOT), make_serial_framing("cobs8")
    rng = random.Random(12)
    learned: dict[int, float] = {}  # robot -> wall time its get first returned VALUE
    try:
        wait_for(lambda: "O" in bus.commands and "O" in listener.commands, 30)
        time.sleep(0.5)  # let both drivers finish opening (they sleep after the open command)
        on_air: list[can.Message] = []  # the CAN robots' frames of the last step
        bridge_seen = 0
        for step in range(1, 200):
            started = time.monotonic()
            from_bridge, bridge_seen = bus.sent[bridge_seen:], len(bus.sent)
            for frame in from_bridge:
                listener.inject(frame)  # the recorder hears the bridge as every node on the bus does
            heard = [(f.arbitration_id & 0xFF, decode(bytes(f.data))) for f in on_air + from_bridge]
            for robot, engine in robots.items():
                for sender, msg in heard:
                    if sender != robot and rng.random() >= DROP:
                        engine.receive(msg)
                if engine.get(KEY) == VALUE and robot not in learned:
                    learned[robot] = time.time()
            if step == 5:
                radio_robot.put(KEY, VALUE)  # the write, on the far side of the bridge
            for msg in radio_robot.drain(1):
                for unit in cobs8.encode(msg):
                    radio.write(unit)
            on_air = [_frame(robot, msg) for robot, engine in robots.items() for msg in engine.drain(1)]
            for frame in on_air:
                bus.inject(frame)
                listener.inject(frame)
            if len(learned) == len(robots) and all(time.time() - t > 3 * STEP for t in learned.values()):
                break  # every robot has held it for a few steps: their messages show it
            time.sleep(max(0.0, STEP - (time.monotonic() - started)))
        wait_for(lambda: capture.exists() and capture.read_text().count("\n") >= 20, 10)
        time.sleep(0.5)
    finally:
        _out, bridge_err = stop(bridge)
        _out, record_err = stop(recorder)
        for peer in (bus, listener, radio):
            peer.close()
    assert bridge.returncode == 0, bridge_err
    assert recorder.returncode == 0, record_err
    assert len(learned) == len(robots), "the write did not reach every CAN robot"

    analyzed = run_vstig("analyze", str(capture), "--json")
    assert analyzed.returncode == 0, analyzed.stderr
    report = json.loads(analyzed.stdout)
    (write,) = [w for w in report["writes"] if (w["key"], w["value"]) == (KEY, VALUE)]
    assert write["robot"] == RADIO_ROBOT and write["senders_total"] == len(CAN_ROBOTS) + 1  # + the bridge
    assert write["converged_after_s"] is not None
    analyzed_end = write["t"] + write["converged_after_s"]
    logged_end = max(learned.values())
    print(f"analyze: converged {analyzed_end - logged_end:+.4f} s from the robots' logs")
    assert abs(analyzed_end - logged_end) <= STEP, (analyzed_end, logged_end, learned)
