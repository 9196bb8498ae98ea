"""The gateway's commands in one process, against robots on a pty radio and python-can's virtual bus.

Run by tests/cli/test_core_install.py with the python of the venv under test (a
core-only install, or the development venv): `python core_session.py FOLDER`.
Needs only what the core install brings (no pytest). The virtual bus reaches only
its own process, so every command runs here, one after the other, through the
CLI's `run` (the console script's body), while the robots run in a thread.
Prints one JSON object: each command's exit status and output, what the robots
hold afterwards, and which of the extras' libraries ended up in `sys.modules`.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

import can
from robots import PtyRobot, Robot

import vstig_hw
import vstig_hw.native
from vstig_cli.main import run
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.wire import Message

EXTRAS_LIBRARIES = ("numpy", "numba", "llvmlite", "matplotlib", "zenoh", "mcap", "rosbags", "foxglove")
STEP = 0.02  # the robots' control period in seconds


class VirtualCanRobot(Robot):
    """A robot on python-can's virtual bus (this process only), speaking the vstig CAN framing."""

    def __init__(self, robot_id: int, channel: str) -> None:
        super().__init__(robot_id)
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.framing = CanFraming(CanIdScheme(), sender=robot_id)

    def _heard(self) -> list[Message]:
        heard: list[Message] = []
        while (frame := self.bus.recv(0)) is not None:
            heard.extend(self.framing.feed(frame))
        return heard

    def _send(self, messages: list[Message]) -> None:
        for msg in messages:
            for frame in self.framing.encode(msg):
                self.bus.send(frame)

    def close(self) -> None:
        self.bus.shutdown()


class Swarm(threading.Thread):
    """Steps every robot each control period; `lock` guards their engines against the main thread."""

    def __init__(self, robots: list[Robot]) -> None:
        super().__init__(daemon=True)
        self.robots = robots
        self.lock = threading.Lock()
        self.running = True

    def run(self) -> None:
        while self.running:
            with self.lock:
                for robot in self.robots:
                    robot.step()
            time.sleep(STEP)


def vstig(*args: str) -> dict[str, Any]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run(list(args))
    return {"code": code, "out": out.getvalue(), "err": err.getvalue()}


def session(folder: Path) -> dict[str, Any]:
    channel = f"core-{os.getpid()}"
    bus = f"can:virtual:{channel}"
    radio = PtyRobot(11, watch=())  # answers and relays, never asks: nothing piles up on a pty nobody reads
    canbot = VirtualCanRobot(21, channel)
    swarm = Swarm([radio, canbot])
    runs: dict[str, dict[str, Any]] = {}
    capture = str(folder / "bus.log")
    try:
        canbot.put(1, 500)  # reaches the radio robot only through the bridge
        swarm.start()
        runs["bridge"] = vstig("bridge", bus, radio.spec, "--robot-id", "200", "--for", "2")
        with swarm.lock:
            canbot.put(2, 777)  # heard while sniffing and recording; the radio robot learns it only from the replay
        runs["sniff"] = vstig("sniff", bus, "--jsonl", "--for", "1")
        runs["record"] = vstig("record", bus, "-o", capture, "--for", "1")
        runs["decode"] = vstig("decode", capture, "--format", "jsonl")
        runs["replay"] = vstig("replay", capture, "--onto", radio.spec, "--ignore-timestamps")
        time.sleep(10 * STEP)  # the radio robot takes in what the replay sent
        runs["put"] = vstig("put", "3", "4242", "--on", radio.spec, "--robot-id", "99")
        runs["get"] = vstig("get", "2", "--on", bus, "--wait", "1")
    finally:
        swarm.running = False
        swarm.join(timeout=2)
        radio.close()
        canbot.close()
    return {
        "runs": runs,
        "radio": {str(key): radio.value(key) for key in (1, 2, 3)},
        "package": vstig_hw.__file__,
        "pure": vstig_hw.native.why_pure,  # "": the compiled data path ran
        "imported": sorted(name for name in EXTRAS_LIBRARIES if name in sys.modules),
    }


if __name__ == "__main__":
    print(json.dumps(session(Path(sys.argv[1]))), file=sys.__stdout__)
