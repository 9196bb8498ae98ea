"""`vstig bridge` between swarms that speak Buzz or BittyBuzz and our own radios, as subprocesses."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import can
import pytest
from bbz_swarm import KilobotSwarm
from peers import PtyPeer, SlcanAdapter, run_vstig, start_vstig, stop, wait_for

from vstig_hw import Message, Op, Stigmergy, decode, encode
from vstig_hw.engine import larger_value_wins
from vstig_hw.framing import make_serial_framing

X = 41  # BittyBuzz's string id of "x" in every build


def test_bittybuzz_kilobots_and_can_converge_with_both_clocks(tmp_path: Path) -> None:
    deployment = tmp_path / "kilobots.toml"
    deployment.write_text('[keys]\nx = { key = 1, type = "int16" }\n', encoding="utf-8")
    adapter, radio = SlcanAdapter(), PtyPeer()
    swarm = KilobotSwarm(radio, [11, 12, 13], [X])
    for robot in swarm.robots:  # the paper's task: every robot puts its id; here the higher id wins
        robot.put(X, robot.rid)
    bridge = start_vstig("bridge", f"can:slcan:{adapter.path}",
                         f"serial:{radio.path}?framing=kilobot&dialect=bittybuzz&deployment={deployment}",
                         "--robot-id", "200")
    try:
        wait_for(lambda: "O" in adapter.commands, 30)
        swarm.start()
        # A CAN robot joins with a higher id at timestamp 1: the same version number the Kilobots started at.
        adapter.inject(can.Message(arbitration_id=0x600 | 40, data=encode(Message(Op.PUT, 1, 40, 1, 40)),
                                   is_extended_id=False))
        wait_for(lambda: all(e is not None and e.value == 40 for e in swarm.held(X)), 30)
        # A Kilobot writes: its next lamport becomes the next timestamp on CAN, writer kept.
        swarm.act(13, X, -7)

        def on_can(value: int) -> list[Message]:
            return [m for m in (decode(bytes(f.data)) for f in list(adapter.sent)) if m.key == 1 and m.value == value]

        wait_for(lambda: bool(on_can(0xFFF9)), 30)
        wait_for(lambda: all(e is not None and e.value == -7 for e in swarm.held(X)), 30)
    finally:
        _out, err = stop(bridge)
        swarm.stop()
        adapter.close()
        radio.close()
    assert bridge.returncode == 0, err
    kilobot_write = on_can(0xFFF9)[0]
    winner = next(e for e in swarm.held(X) if e is not None)
    assert (kilobot_write.op, kilobot_write.robot) == (Op.PUT, 13)
    assert kilobot_write.timestamp == 2 and winner.lamport == 3  # lamport 3 = one past the bridge's 2
    # What the bridge told the Kilobots: PUTs only, each lamport one step past the previous.
    sent = [m for m in swarm.from_bridge if m[2] == X]
    assert sent and all(m[0] == 1 for m in sent)
    lamports = [m[5] for m in sent]
    assert all(1 <= (b - a) & 0xFF <= 2 or b == a for a, b in itertools.pairwise(lamports)), lamports
    assert sent[0][1] == 40 and sent[0][4] == 40  # the CAN robot's version, under its own id


KH4_ROBOT = Path(__file__).with_name("kh4_robot.py")
FRAME = 64


def _start_khepera(robot_id: int, *options: str) -> tuple[subprocess.Popen[str], int]:
    """A stand-in Khepera (kh4_robot.py: its options) and the port it listens on."""
    robot = subprocess.Popen([sys.executable, str(KH4_ROBOT), str(robot_id), str(FRAME), *options],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert robot.stdout is not None
    first = robot.stdout.readline().split()
    assert first[:1] == ["port"], first
    return robot, int(first[1])


def test_blabbermouth_kheperas_and_a_pty_robot_converge_on_the_largest_id(tmp_path: Path) -> None:
    deployment = tmp_path / "kheperas.toml"
    deployment.write_text('[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }\n', encoding="utf-8")
    kheperas = [_start_khepera(robot_id) for robot_id in (5, 6, 7)]
    lines: dict[int, list[str]] = {index: [] for index in range(3)}
    readers = [threading.Thread(target=_collect, args=(robot.stdout, lines[i]), daemon=True)
               for i, (robot, _) in enumerate(kheperas)]
    for reader in readers:
        reader.start()
    radio = PtyPeer()
    far_robot = Stigmergy(300, onconflict=larger_value_wins)
    far_robot.put(1, 300)  # the paper's task: every robot puts its id
    framing = make_serial_framing("cobs8")
    addresses = ",".join(f"127.0.0.1:{port}" for _, port in kheperas)
    bridge = start_vstig("bridge", f"blabbermouth:{addresses}?size={FRAME}&deployment={deployment}",
                         f"serial:{radio.path}?framing=cobs8", "--robot-id", "200", "--larger-value-wins")

    def radio_robot_step() -> None:
        for msg in framing.feed(radio.read(0.05)):
            far_robot.receive(msg)
        far_robot.get(1)
        for msg in far_robot.drain():
            radio.write(b"".join(framing.encode(msg)))

    try:
        wait_for(lambda: all(lines[i] and lines[i][-1] == "leader 300 1 300" for i in range(3)), 60,
                 step=radio_robot_step)
    finally:
        _out, err = stop(bridge)
        for robot, _ in kheperas:
            robot.terminate()
            robot.wait(timeout=10)
        radio.close()
    assert bridge.returncode == 0, err
    every_line = [line for i in range(3) for line in lines[i]]
    assert not [line for line in every_line if line.startswith("bad")], every_line  # byte-exact Buzz
    assert far_robot.entry(1) == (300, 1, 300)
    assert "relayed=" in err


def test_sniffing_a_khepera_swarm_relays_it_whole_and_decodes_it(tmp_path: Path) -> None:
    """Without the relay the robots never hear each other; a sniffer relays and only listens."""
    deployment = tmp_path / "kheperas.toml"
    deployment.write_text('[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }\n', encoding="utf-8")
    kheperas = [_start_khepera(robot_id) for robot_id in (5, 6, 7)]
    lines: dict[int, list[str]] = {index: [] for index in range(3)}
    for i, (robot, _) in enumerate(kheperas):
        threading.Thread(target=_collect, args=(robot.stdout, lines[i]), daemon=True).start()
    addresses = ",".join(f"127.0.0.1:{port}" for _, port in kheperas)
    sniffer = start_vstig("sniff", f"blabbermouth:{addresses}?size={FRAME}&deployment={deployment}", "--jsonl")
    rows: list[str] = []
    threading.Thread(target=_collect, args=(sniffer.stdout, rows), daemon=True).start()
    try:
        wait_for(lambda: all(lines[i] and lines[i][-1] == "leader 7 1 7" for i in range(3)), 60)
        wait_for(lambda: len(rows) >= 3, 30)
    finally:
        stop(sniffer)
        for robot, _ in kheperas:
            robot.terminate()
            robot.wait(timeout=10)
    decoded = [json.loads(row) for row in rows]
    assert {(r["op"], r["key"], r["value"], r["timestamp"], r["robot"]) for r in decoded} >= {("PUT", 1, 7, 1, 7)}
    assert all(r["key"] == 1 for r in decoded)
    assert not [line for i in range(3) for line in lines[i] if line.startswith("bad")]


def _collect(stream: Any, into: list[str]) -> None:
    for line in stream:
        into.append(line.strip())


def test_record_and_decode_a_khepera_swarm(tmp_path: Path) -> None:
    deployment = tmp_path / "kheperas.toml"
    deployment.write_text('[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }\n', encoding="utf-8")
    kheperas = [_start_khepera(robot_id) for robot_id in (5, 9)]
    capture = tmp_path / "kheperas.cap"
    addresses = ",".join(f"127.0.0.1:{port}" for _, port in kheperas)
    try:
        done = run_vstig("record", f"blabbermouth:{addresses}?size={FRAME}&deployment={deployment}",
                         "-o", str(capture), "--for", "2")
    finally:
        for robot, _ in kheperas:
            robot.terminate()
            robot.wait(timeout=10)
    assert done.returncode == 0, done.stderr
    decoded = run_vstig("decode", str(capture), "--format", "jsonl", "--deployment", str(deployment))
    assert decoded.returncode == 0, decoded.stderr
    rows = [json.loads(line) for line in decoded.stdout.splitlines()]
    assert ("PUT", 1, 9, 1, 9) in {(r["op"], r["key"], r["value"], r["timestamp"], r["robot"]) for r in rows}
    undeployed = run_vstig("decode", str(capture))
    assert undeployed.returncode == 1 and "--deployment" in undeployed.stderr
    assert len(undeployed.stderr.strip().splitlines()) == 1 and "Traceback" not in undeployed.stderr


GATEWAY = 200
TWO_KEYS = '[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "int16" }\nmarker = { key = 2, type = "int16" }\n'


class KheperaLab:
    """Stand-in Kheperas, each printing what it hears (`--trace`), beside a cobs8 radio robot, both bridged."""

    def __init__(self, tmp_path: Path, robots: dict[int, tuple[str, ...]], keys: str = TWO_KEYS) -> None:
        deployment = tmp_path / "kheperas.toml"
        deployment.write_text(keys, encoding="utf-8")
        self.kheperas = {rid: _start_khepera(rid, "--trace", *options) for rid, options in robots.items()}
        self.lines: dict[int, list[str]] = {rid: [] for rid in robots}
        for rid, (robot, _) in self.kheperas.items():
            threading.Thread(target=_collect, args=(robot.stdout, self.lines[rid]), daemon=True).start()
        self.radio = PtyPeer()
        self.far_robot = Stigmergy(300)
        self.radio_asks = True  # the radio robot asks for `leader` at every step
        self.framing = make_serial_framing("cobs8")
        addresses = ",".join(f"127.0.0.1:{port}" for _, port in self.kheperas.values())
        self.bridge = start_vstig("bridge", f"blabbermouth:{addresses}?size={FRAME}&deployment={deployment}",
                                  f"serial:{self.radio.path}?framing=cobs8", "--robot-id", str(GATEWAY))

    def radio_step(self) -> None:
        """The radio robot's control step: hear, ask for `leader` (if `radio_asks`), send."""
        for msg in self.framing.feed(self.radio.read(0.05)):
            self.far_robot.receive(msg)
        if self.radio_asks:
            self.far_robot.get(1)
        for msg in self.far_robot.drain():
            self.radio.write(b"".join(self.framing.encode(msg)))

    def heard(self, rid: int, sender: int, kind: str, key: str) -> list[tuple[str, ...]]:
        """(value, ts, writer) of every `kind` message for `key` that Khepera `rid` heard from `sender`."""
        prefix = f"heard {sender} {kind} {key} "
        return [tuple(line[len(prefix):].split()) for line in list(self.lines[rid]) if line.startswith(prefix)]

    def holds(self, rid: int, entry: str) -> bool:
        return f"leader {entry}" in self.lines[rid]

    def versions(self, rid: int, ts: str, writer: str) -> set[str]:
        """Every value Khepera `rid` held, or heard in any message, at (ts, writer) of `leader`."""
        held = {line.split()[1] for line in list(self.lines[rid])
                if line.startswith("leader ") and line.split()[2:] == [ts, writer]}
        return held | {value for sender in (*self.kheperas, GATEWAY) for kind in ("put", "query")
                       for value, *version in self.heard(rid, sender, kind, "leader") if version == [ts, writer]}

    def close(self) -> str:
        _out, err = stop(self.bridge)
        for robot, _ in self.kheperas.values():
            robot.terminate()
            robot.wait(timeout=10)
        self.radio.close()
        assert self.bridge.returncode == 0, err
        assert not [line for lines in self.lines.values() for line in lines if line.startswith("bad")]
        return err


def test_an_engine_bridge_does_not_echo_a_kheperas_put_back_to_the_kheperas(tmp_path: Path) -> None:
    """Every Khepera heard robot 5's PUT through the relay: the bridge re-broadcasts it to the radio only.

    The Kheperas' own re-broadcasts (Buzz stores and re-broadcasts) stay; the bridge's
    copy under its own id would be a fourth PUT of the same entry on their medium.
    """
    lab = KheperaLab(tmp_path, {5: (), 6: ("--silent",), 7: ("--silent",)})
    # A GET from the radio carrying an older entry, reaching the bridge after it stored robot 5's PUT (a loaded
    # machine), is rightly answered on every link (DECISIONS: "Which links get a PUT back"): an answer, not an
    # echo. So here the radio robot asks nothing and only hears.
    lab.radio_asks = False
    try:
        wait_for(lambda: lab.far_robot.entry(1) == (5, 1, 5) and all(lab.holds(rid, "5 1 5") for rid in (6, 7))
                 and all(lab.heard(6, rid, "put", "leader") for rid in (5, 7)), 60, step=lab.radio_step)
        # A marker from the radio crosses after anything the bridge queued for the Kheperas before it.
        lab.far_robot.put(2, 1)
        wait_for(lambda: all(lab.heard(rid, GATEWAY, "put", "marker") for rid in (5, 6, 7)), 60, step=lab.radio_step)
    finally:
        err = lab.close()
    medium = {sender: len(lab.heard(6, sender, "put", "leader")) for sender in (5, 7, GATEWAY)}
    print("leader PUTs Khepera 6 heard, by sender:", medium)
    assert medium[5] >= 1 and medium[7] >= 1  # the original and robot 7's own re-broadcast
    assert medium[GATEWAY] == 0, medium  # no echo on the medium the PUT came from
    assert not lab.heard(5, GATEWAY, "put", "leader") and not lab.heard(7, GATEWAY, "put", "leader")
    assert "not_echoed=" in err


def test_an_engine_bridge_still_repairs_a_khepera_that_missed_the_put(tmp_path: Path) -> None:
    """Khepera 6 missed robot 5's newer PUT: its GET carries its older entry, and the bridge answers it."""
    lab = KheperaLab(tmp_path, {5: ("--ts", "2"), 6: ("--deaf", "1.5"), 7: ("--silent",)})
    try:
        wait_for(lambda: lab.far_robot.entry(1) == (5, 2, 5), 60, step=lab.radio_step)
        wait_for(lambda: ("5", "2", "5") in lab.heard(6, GATEWAY, "put", "leader"), 60, step=lab.radio_step)
        wait_for(lambda: lab.holds(6, "5 2 5"), 60, step=lab.radio_step)
    finally:
        lab.close()
    assert lab.heard(5, 6, "query", "leader")[0] == ("6", "1", "6")  # what 6 asked with: its own, older entry


FLOAT16_KEYS = ('[buzz]\nstigmergy = 1\n[keys]\nleader = { key = 1, type = "float16" }\n'
                'marker = { key = 2, type = "int16" }\n')


@pytest.mark.parametrize(("written", "bits"), [("0.1", "float:3dcccccd"), ("0.3", "float:3e99999a")])
def test_a_float_that_float16_cannot_carry_stays_the_writers_on_every_khepera(tmp_path: Path, written: str,
                                                                              bits: str) -> None:
    """Khepera 9 writes 0.1 (or 0.3) under a float16 key: no robot may hold another value at its version.

    Khepera 6 wrote 0.5 (a float16 exactly) and is deaf for 1.5 s, asking all the while
    with its older entry: the bridge answers it, and any answer carrying 9's version
    reaches every Khepera. The bridge refuses 9's write (`drop_unmapped`), so the radio
    robot never holds that version and the Kheperas hold only what 9 wrote.
    """
    lab = KheperaLab(tmp_path, {9: ("--float", written, "--ts", "2"), 6: ("--float", "0.5", "--deaf", "1.5"),
                                7: ("--silent",)}, FLOAT16_KEYS)
    try:
        wait_for(lambda: all(lab.versions(rid, "2", "9") for rid in (6, 7, 9)) and lab.far_robot.entry(1), 60,
                 step=lab.radio_step)
        # Steady: Khepera 6 has asked twice with 9's version since it started hearing.
        wait_for(lambda: sum(version[1:] == ("2", "9") for version in lab.heard(7, 6, "query", "leader")) >= 2, 30,
                 step=lab.radio_step)
    finally:
        err = lab.close()
    assert {rid: lab.versions(rid, "2", "9") for rid in (6, 7, 9)} == {6: {bits}, 7: {bits}, 9: {bits}}
    assert all([line for line in lab.lines[rid] if line.startswith("leader ")][-1] == f"leader {bits} 2 9"
               for rid in (6, 7, 9))
    assert lab.far_robot.entry(1) == (0x3800, 1, 6)  # the radio robot holds 6's exact write, never 9's
    assert "drop_unmapped=" in err
