"""ROSBuzz drones on XBee radios (rosbuzz_robot.py: XbeeMav's packets, written from its C++) and a `vstig bridge`
with `dialect=buzz` agree on the same table with a robot on a cobs8 radio.

The winning drone sends its packets as fragments only, which the other drones do not read
(they reassemble nothing, as ROSBuzz's Buzz messages never need it): they and the radio robot
can only learn its entry from the gateway, which reassembles the fragments and sends the entry
on in `S` packets and cobs8 frames.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from peers import PtyPeer, start_vstig, stop, wait_for
from xbee_network import XBeeNetwork

from vstig_hw import Stigmergy
from vstig_hw.engine import larger_value_wins
from vstig_hw.framing import make_serial_framing

DRONE = Path(__file__).with_name("rosbuzz_robot.py")
DEPLOYMENT = '[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }\n'


def _collect(stream: object, lines: list[str]) -> None:
    lines.extend(line.strip() for line in stream)  # type: ignore[attr-defined]


def _last_entry(said: list[str]) -> str | None:
    return next((line for line in reversed(said) if line.startswith("leader ")), None)


@pytest.mark.parametrize("api", [1, 2])
def test_rosbuzz_drones_the_gateway_and_a_radio_robot_agree_on_the_largest_id(api: int, tmp_path: Path) -> None:
    deployment = tmp_path / "drones.toml"
    deployment.write_text(DEPLOYMENT, encoding="utf-8")
    with XBeeNetwork(loss=0.2, delay=0.005, jitter=0.01, seed=api) as network:
        gateway = network.module(0x0013A20040000001, api=api)
        modules = [network.module(0x0013A20040000010 + i, api=api) for i in range(3)]
        drones, lines = [], []
        for i, module in enumerate(modules):
            args = [sys.executable, str(DRONE), str(5 + i), module.path, "--api", str(api)]
            drone = subprocess.Popen([*args, *(["--fragment"] if i == 2 else [])], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
            said: list[str] = []
            threading.Thread(target=_collect, args=(drone.stdout, said), daemon=True).start()
            drones.append(drone)
            lines.append(said)
        radio = PtyPeer()
        far_robot = Stigmergy(250, onconflict=larger_value_wins)  # it only asks: the drones put their ids
        cobs8 = make_serial_framing("cobs8")
        spec = f"serial:{gateway.path}?framing=xbee&dialect=buzz&deployment={deployment}&api={api}"
        bridge = start_vstig("bridge", spec, f"serial:{radio.path}", "--robot-id", "200", "--larger-value-wins")

        writers: set[int] = set()

        def radio_robot_step() -> None:
            for msg in cobs8.feed(radio.read(0.05)):
                writers.add(msg.robot)
                far_robot.receive(msg)
            far_robot.get(1)
            for msg in far_robot.drain():
                radio.write(b"".join(cobs8.encode(msg)))

        try:
            wait_for(lambda: all(_last_entry(said) == "leader 7 1 7" for said in lines)
                     and far_robot.entry(1) == (7, 1, 7), 60, step=radio_robot_step)
        finally:
            _out, err = stop(bridge)
            for drone in drones:
                drone.terminate()
                drone.wait(timeout=10)
            radio.close()
    assert bridge.returncode == 0, err
    assert far_robot.entry(1) == (7, 1, 7)
    everything = [line for said in lines for line in said]
    assert not [line for line in everything if line.startswith("bad")], everything  # our Buzz parses exactly
    assert sum(line.startswith("module 0013A200") for line in everything) == 3  # their modules answered SL and SH
    assert 7 in writers
    link = next(line for line in err.splitlines() if line.startswith(f"{os.path.basename(gateway.path)}: "))
    # Lost fragments leave packets that never complete: counted as they are evicted or go stale, nothing else.
    assert "drop_fragment_bad" not in link and "drop_buzz" not in link and "drop_unmapped" not in link, link
