"""A guarded `vstig bridge` process between a CAN bus (python-can's slcan driver on a pty) and a pty radio.

On the CAN bus: an honest robot (id 50) and attackers who send (a) a timestamp jump,
(b) a flood, (c) writes from a denied robot and (d) writes to a forbidden key. The
honest robot hears all of it and, as the protocol says, relays what is new under its
own id. On the radio: two honest robots (ids 20 and 21). Every honest robot runs the
paper's task (put its id under key 1, get it every control step, larger value wins).
With the guard, the radio robots never see any attack and the task converges; the same
run with the guard off shows the radio robots poisoned, so the test can fail.
"""

from __future__ import annotations

import json
import os
import re
import time

import pytest
from peers import PtyPeer, SlcanAdapter, has_open, run_vstig, start_vstig, stop, wait_for

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.engine import larger_value_wins
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import can_framing_for
from vstig_hw.links import parse

TASK_KEY = 1
JUMP_KEY = 7  # written honestly by radio robot 21, then forged 30,000 ahead
DENIED_KEY = 8  # written by denied robot 77
FORBIDDEN_KEY = 500  # outside the CAN link's --keys
FLOOD_KEYS = range(200, 300)  # outside --keys too; sender 67 floods them as fast as the adapter takes frames
DENIED, JUMPER, FLOODER, TRESPASSER = 77, 66, 67, 68


class CanBus:
    """The test's side of the slcan adapter: robots on it hear each other and what the bridge sends."""

    def __init__(self, adapter: SlcanAdapter) -> None:
        self.adapter = adapter
        self.robots: list[tuple[Stigmergy, object]] = []
        self._seen = 0
        self._listen = can_framing_for(0)

    def add(self, robot: Stigmergy) -> None:
        self.robots.append((robot, can_framing_for(robot.robot_id)))

    def send(self, msg: Message, sender: int, hear: bool = True) -> None:
        for frame in can_framing_for(sender).encode(msg):
            self.adapter.inject(frame)
        if hear:
            for robot, _ in self.robots:
                robot.receive(msg)

    def step(self) -> None:
        sent = self.adapter.sent
        for frame in sent[self._seen:len(sent)]:
            for msg in self._listen.feed(frame):
                for robot, _ in self.robots:
                    robot.receive(msg)
        self._seen = len(sent)
        for robot, _ in self.robots:
            for msg in robot.drain(4):
                self.send(msg, robot.robot_id, hear=False)
                for other, _ in self.robots:
                    if other is not robot:
                        other.receive(msg)


class Radio:
    """The robots on the pty radio: they hear each other and the bridge."""

    def __init__(self, peer: PtyPeer) -> None:
        self.peer = peer
        self.robots: list[Stigmergy] = []
        self._framing = make_serial_framing("cobs8")
        self.heard: list[Message] = []  # everything the bridge sent here

    def step(self) -> None:
        while data := self.peer.read(0):
            for msg in self._framing.feed(data):
                self.heard.append(msg)
                for robot in self.robots:
                    robot.receive(msg)
        for robot in self.robots:
            for msg in robot.drain(4):
                for unit in self._framing.encode(msg):
                    self.peer.write(unit)
                for other in self.robots:
                    if other is not robot:
                        other.receive(msg)


def run_swarm(guarded: bool) -> tuple[Radio, Stigmergy, str, str]:
    adapter, peer = SlcanAdapter(), PtyPeer()
    can_spec, radio_spec = f"can:slcan:{adapter.path}", f"serial:{peer.path}?framing=cobs8"
    can_name = parse(can_spec).name
    policies = ["--rate", "50", "--deny", f"{can_name}={DENIED}", "--keys", f"{can_name}=0-99"] if guarded \
        else ["--max-jump", "0"]
    bridge = start_vstig("bridge", can_spec, radio_spec, "--robot-id", "200", "--larger-value-wins", *policies)
    bus, radio = CanBus(adapter), Radio(peer)
    honest = Stigmergy(50, onconflict=larger_value_wins)
    bus.add(honest)
    radio.robots += [Stigmergy(20, onconflict=larger_value_wins), Stigmergy(21, onconflict=larger_value_wins)]
    everyone = [honest, *radio.robots]

    def control_step() -> None:
        for robot in everyone:
            robot.get(TASK_KEY)
        bus.step()
        radio.step()
        time.sleep(0.05)

    try:
        wait_for(lambda: "O" in adapter.commands, 30)
        for robot in everyone:
            robot.put(TASK_KEY, robot.robot_id)
        radio.robots[1].put(JUMP_KEY, 1)
        def ask_until_bridged() -> None:
            # The first PUT may reach the pty before the bridge has opened it (opening flushes input):
            # robot 21 asks each step, and its GET carries the entry across as the PUT would.
            radio.robots[1].get(JUMP_KEY)
            control_step()

        wait_for(lambda: honest.has(JUMP_KEY), 30, step=ask_until_bridged)  # the bridge holds it too

        forged = honest.entry(JUMP_KEY)
        assert forged is not None
        bus.send(Message(Op.PUT, JUMP_KEY, 666, forged.timestamp + 30000, JUMPER), JUMPER)  # (a)
        bus.send(Message(Op.PUT, DENIED_KEY, 777, 1, DENIED), DENIED)  # (c)
        bus.send(Message(Op.PUT, FORBIDDEN_KEY, 888, 1, TRESPASSER), TRESPASSER)  # (d)
        for i in range(600):  # (b)
            bus.send(Message(Op.PUT, FLOOD_KEYS[i % len(FLOOD_KEYS)], i, i // len(FLOOD_KEYS) + 1, FLOODER),
                     FLOODER, hear=i % 50 == 0)  # the honest robot hears (and relays) some of it
        converged = lambda: all(r.get(TASK_KEY) == 50 for r in everyone)  # noqa: E731
        wait_for(converged, 60, step=control_step)
        for _ in range(40):  # two more seconds of traffic: time for anything the bridge lets through to arrive
            control_step()
    finally:
        _out, err = stop(bridge)
        adapter.close()
        peer.close()
    assert bridge.returncode == 0, err
    return radio, honest, err, can_name


def attacks_heard(radio: Radio) -> dict[str, list[Message]]:
    return {
        "jump": [m for m in radio.heard if m.key == JUMP_KEY and m.value == 666],
        "denied": [m for m in radio.heard if m.key == DENIED_KEY],
        "forbidden": [m for m in radio.heard if m.key == FORBIDDEN_KEY],
        "flood": [m for m in radio.heard if m.key in FLOOD_KEYS],
    }


@pytest.mark.slow
def test_a_guarded_bridge_keeps_every_attack_off_the_radio_and_the_task_converges() -> None:
    radio, honest, err, can_name = run_swarm(guarded=True)
    assert attacks_heard(radio) == {"jump": [], "denied": [], "forbidden": [], "flood": []}
    for robot in radio.robots:
        assert robot.entry(TASK_KEY) is not None and robot.get(TASK_KEY) == 50
        assert robot.entry(JUMP_KEY) == (1, 1, 21)
        assert not robot.has(DENIED_KEY) and not robot.has(FORBIDDEN_KEY)
    assert honest.entry(JUMP_KEY) is not None and honest.entry(JUMP_KEY).value == 666  # its own medium: poisoned
    can_line = next(line for line in err.splitlines() if line.startswith(f"{can_name}:"))  # the final summary
    for counter in ("drop_jump=", "drop_untrusted=", "drop_key=", "drop_rate="):
        assert counter in can_line, err


@pytest.mark.slow
def test_the_same_run_without_the_guard_poisons_the_radio() -> None:
    radio, _honest, err, _name = run_swarm(guarded=False)
    heard = attacks_heard(radio)
    assert heard["jump"] and heard["denied"] and heard["forbidden"] and heard["flood"], err
    for robot in radio.robots:
        assert robot.entry(JUMP_KEY) is not None and robot.entry(JUMP_KEY).value == 666
        assert robot.get(DENIED_KEY) == 777 and robot.get(FORBIDDEN_KEY) == 888


@pytest.mark.parametrize(("args", "message"), [
    (["--trust", "ttyX=1-"], "'ttyX=1-': bad ids '1-'"),
    (["--keys", "ttyX"], "'ttyX' is not LINK=KEYS"),
    (["--keys", "ttyX=40000"], "within 0..32767"),
    (["--deny", "nosuch=3"], "--deny nosuch: no such link (links here: ttyX)"),
    (["--trust", "ttyX=3"], "--trust ttyX: this medium does not name its senders"),
    (["--keys", "ttyX=1", "--keys", "ttyX=2"], "--keys ttyX given twice"),
    (["--read-only", "ttyY"], "--read-only ttyY: no such link"),
    (["--max-jump", "-1"], "--max-jump"),
    (["--rate", "0"], "--rate"),
])
def test_bad_guard_options_are_one_line_usage_errors(args: list[str], message: str) -> None:
    for command in (["bridge", "serial:/dev/ttyX", "--robot-id", "1"], ["sniff", "serial:/dev/ttyX"]):
        done = run_vstig(*command, *args)
        assert done.returncode == 2, done.stderr
        assert message in done.stderr and "Traceback" not in done.stderr


def sniff_a_radio(heard: list[Message], *options: str) -> tuple[str, str]:
    """What `vstig sniff` (run for 4 s, on a wide table) prints, having heard `heard` on a cobs8 radio."""
    radio = PtyPeer()
    framing = make_serial_framing("cobs8")
    sniffer = start_vstig("sniff", f"serial:{radio.path}?framing=cobs8", "--for", "4", *options,
                          env={**os.environ, "COLUMNS": "250"})
    try:
        wait_for(lambda: has_open(sniffer.pid, radio.path), 30)  # the sniffer never transmits: look at its fds
        time.sleep(0.3)  # pyserial flushes the input right after opening
        radio.write(b"".join(unit for msg in heard for unit in framing.encode(msg)))
        out, err = sniffer.communicate(timeout=60)
    finally:
        if sniffer.poll() is None:
            stop(sniffer)
        radio.close()
    assert sniffer.returncode == 0, err
    return out, err


A_KEY_THEN_A_JUMP = [Message(Op.PUT, 5, 1, 1, 9), Message(Op.PUT, 5, 2, 30000, 9)]


def test_sniff_shows_and_counts_refusals_and_warns_once_of_a_flapping_key() -> None:
    heard = list(A_KEY_THEN_A_JUMP)
    for ts in range(1, 30):  # robots 4 and 6 fight over key 12: a conflict at every timestamp
        heard += [Message(Op.PUT, 12, 1, ts, 4), Message(Op.PUT, 12, 2, ts, 6)]
    out, err = sniff_a_radio(heard, "--flap", "3")
    assert "drop_jump=1" in out  # the table's caption
    # key 5's row: value 1, ts 1, robot 9 (the jump never became the entry), one PUT, 1 refused for a jump
    assert re.search(r"^ *5 +1 +1 +9 +\S+ +1 +0 +0 +1 jump *$", out, flags=re.M), out
    warnings = [line for line in err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "key 12" in warnings[0] and "robots 4 and 6" in warnings[0], err


def test_sniff_jsonl_marks_what_a_guarded_bridge_would_refuse_and_hides_it_only_when_asked() -> None:
    out, _ = sniff_a_radio(A_KEY_THEN_A_JUMP, "--jsonl")
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert [(r["timestamp"], r["refused"]) for r in rows] == [(1, None), (30000, "drop_jump")]
    out, _ = sniff_a_radio(A_KEY_THEN_A_JUMP, "--jsonl", "--hide-refused")
    assert [json.loads(line)["timestamp"] for line in out.splitlines() if line.startswith("{")] == [1]


def test_bridge_read_only_link_is_heard_but_never_relayed() -> None:
    classroom, lab = PtyPeer(), PtyPeer()
    framing = make_serial_framing("cobs8")
    specs = [f"serial:{peer.path}?framing=cobs8" for peer in (classroom, lab)]
    bridge = start_vstig("bridge", *specs, "--robot-id", "200", "--read-only", parse(specs[0]).name)
    heard: dict[str, list[Message]] = {"classroom": [], "lab": []}
    try:
        def both_write() -> None:  # again and again until the bridge has both ports open
            classroom.write(framing.encode(Message(Op.PUT, 3, 11, 1, 5))[0])
            lab.write(framing.encode(Message(Op.PUT, 4, 22, 1, 9))[0])
            for name, peer in (("classroom", classroom), ("lab", lab)):
                heard[name] += framing.feed(peer.read(0.05))

        wait_for(lambda: any(m.key == 4 for m in heard["classroom"]) and any(m.key == 3 for m in heard["classroom"]),
                 30, step=both_write)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            both_write()
    finally:
        _out, err = stop(bridge)
        classroom.close()
        lab.close()
    assert bridge.returncode == 0, err
    assert {m.key for m in heard["classroom"]} == {3, 4}  # the lab's data reaches the classroom, its own echoes back
    assert {m.key for m in heard["lab"]} == {4}  # nothing the classroom wrote reaches the lab


def test_sniff_learn_refuses_a_first_write_far_from_zero_and_a_climb_in_steps() -> None:
    climb = [Message(Op.PUT, 6, 1, 1 + 255 * n, 9) for n in range(3)]  # 1, 256, 511: each within 255
    out, _ = sniff_a_radio([Message(Op.PUT, 5, 1, 1, 4), Message(Op.PUT, 7, 1, 32767, 9), *climb],
                           "--jsonl", "--learn", "0")
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    assert [(r["key"], r["timestamp"], r["refused"]) for r in rows] == [
        (5, 1, None), (7, 32767, "drop_jump"), (6, 1, None), (6, 256, None), (6, 511, "drop_jump")]
