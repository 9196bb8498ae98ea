"""`vstig put` and `vstig get` as subprocesses against robots on pty radios.

Each robot is a thread on a pty's master side running its own engine; the
variants play what a field test meets: a robot whose answers arrive late, one
that never stores what it hears, one whose program keeps overwriting the key,
a radio that echoes what it is sent, and a transmit-only overhead controller.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest
from peers import PtyPeer, SlcanAdapter, run_vstig

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import can_framing_for

Program = Callable[["RadioRobot", Message], None]


class RadioRobot(threading.Thread):
    """A robot on the far end of a cobs8 radio: hears, answers, re-broadcasts, every few ms.

    `delay` holds everything it sends for that long (a slow radio, or a robot that
    answers once per control step); `program` replaces the plain `engine.receive`
    of each message heard, and may queue extra messages in `say`.
    """

    def __init__(self, robot_id: int, *, delay: float = 0.0, program: Program | None = None) -> None:
        super().__init__(daemon=True)
        self.radio = PtyPeer()
        self.link = f"serial:{self.radio.path}"
        self.engine = Stigmergy(robot_id)
        self.framing = make_serial_framing("cobs8")
        self.delay = delay
        self.program = program
        self.say: list[Message] = []
        self.heard: list[Message] = []
        self.running = True

    def holding(self, key: int, value: int, timestamp: int) -> RadioRobot:
        for _ in range(timestamp):
            self.engine.put(key, value)
        self.engine.drain()
        return self

    def run(self) -> None:
        pending: list[tuple[float, bytes]] = []
        while self.running:
            for msg in self.framing.feed(self.radio.read(0.005)):
                self.heard.append(msg)
                if self.program:
                    self.program(self, msg)
                else:
                    self.engine.receive(msg)
            now = time.monotonic()
            outgoing = [*self.engine.drain(), *self.say]
            self.say.clear()
            pending.extend((now + self.delay, self.framing.encode(msg)[0]) for msg in outgoing)
            while pending and pending[0][0] <= now:
                self.radio.write(pending.pop(0)[1])

    def __enter__(self) -> RadioRobot:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.running = False
        self.join(timeout=2)
        self.radio.close()


def test_get_prints_the_value_a_neighbour_holds_and_put_overrides_it() -> None:
    with RadioRobot(12).holding(3, 500, timestamp=4) as robot:
        got = run_vstig("get", "3", "--on", robot.link, "--wait", "1")
        assert got.returncode == 0, got.stderr
        assert got.stdout.strip() == "key=3 value=500 timestamp=4 robot=12"
        put = run_vstig("put", "3", "777", "--on", robot.link, "--robot-id", "99")
        assert put.returncode == 0, put.stderr
        assert "timestamp=5" in put.stdout  # it learned the swarm's timestamp first, so its write is newer
        assert robot.engine.entry(3) == (777, 5, 99)  # exit 0 came after the robot took it


def test_put_whose_learning_answer_arrives_after_the_write_writes_again_and_reports_what_landed() -> None:
    # The field report: the robot's answer to the learning GET came just after the write
    # (ts 1), the robot ignored that stale PUT, and put claimed "timestamp=5" with exit 0.
    with RadioRobot(9, delay=0.8).holding(23, 1, timestamp=5) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "0.5", "--wait", "10")
        assert put.returncode == 0, put.stderr
        assert put.stdout.startswith("put key=23 value=9 timestamp=6 robot=33 on ")
        assert robot.engine.entry(23) == (9, 6, 33)


def test_put_asks_every_control_step_while_learning() -> None:
    with RadioRobot(9, delay=0.8).holding(23, 1, timestamp=5) as robot:
        run_vstig("put", "23", "9", "--on", robot.link, "--learn", "2.0", "--no-confirm")
        gets_before_write = []
        for msg in robot.heard:
            if msg.op is Op.PUT:
                break
            gets_before_write.append(msg)
    assert len(gets_before_write) >= 5  # one a control step (0.1 s) for 2 s, not one in all


def test_put_whose_rebroadcast_is_lost_is_confirmed_by_the_robot_answering_an_empty_get() -> None:
    lost: list[Message] = []

    def loses_its_first_rebroadcast(robot: RadioRobot, msg: Message) -> None:
        robot.engine.receive(msg)
        if msg.op is Op.PUT and msg.robot == 33 and not lost:
            lost.extend(robot.engine.drain())  # the radio lost the frame that would have confirmed it

    with RadioRobot(9, program=loses_its_first_rebroadcast).holding(23, 1, timestamp=5) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "0.3", "--wait", "5")
        asked = [m for m in robot.heard if m.op is Op.GET and m.timestamp == 0]
    assert lost == [Message(Op.PUT, 23, 9, 6, 33)]
    assert put.returncode == 0, put.stderr
    assert put.stdout.startswith("put key=23 value=9 timestamp=6 robot=33 on ")
    assert asked  # the empty GETs it answered


def test_put_over_can_is_confirmed_by_a_robot_on_the_bus() -> None:
    adapter = SlcanAdapter()  # python-can's real slcan driver on the pty: a USB-CAN adapter
    robot = Stigmergy(9)
    for _ in range(5):
        robot.put(23, 1)
    robot.drain()
    bus_framing = can_framing_for(9)
    running = True

    def on_the_bus() -> None:
        done = 0
        while running:
            for frame in adapter.sent[done:]:
                done += 1
                for msg in bus_framing.feed(frame):
                    robot.receive(msg)
            for frame in bus_framing.encode_batch(robot.drain()):
                adapter.inject(frame)
            time.sleep(0.005)

    thread = threading.Thread(target=on_the_bus, daemon=True)
    thread.start()
    try:
        put = run_vstig("put", "23", "9", "--on", f"can:slcan:{adapter.path}", "--robot-id", "33", "--wait", "10")
    finally:
        running = False
        thread.join(timeout=2)
        adapter.close()
    assert put.returncode == 0, put.stderr
    assert put.stdout.startswith("put key=23 value=9 timestamp=6 robot=33 on ")
    assert robot.entry(23) == (9, 6, 33)
    assert {frame.arbitration_id for frame in adapter.sent} <= {0x600 | 33, 0x700 | 33}  # PUTs and GETs as node 33


def test_put_that_no_robot_stores_exits_1_saying_what_the_swarm_holds() -> None:
    def answers_but_never_stores(robot: RadioRobot, msg: Message) -> None:
        if msg.op is Op.GET:
            robot.say.append(Message(Op.PUT, 23, 1, 5, 9))

    with RadioRobot(9, program=answers_but_never_stores) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "0.3", "--wait", "1")
    assert put.returncode == 1 and put.stdout == ""
    (line,) = put.stderr.splitlines()
    assert "no neighbour" in line and "(value=9 timestamp=6 robot=33)" in line
    assert "value=1 timestamp=5 robot=9" in line


def test_put_against_a_robot_that_keeps_overwriting_gives_up_after_its_tries() -> None:
    def insists_on_its_own_value(robot: RadioRobot, msg: Message) -> None:
        robot.engine.receive(msg)
        entry = robot.engine.entry(23)
        if entry is not None and entry.robot != 9:
            robot.engine.put(23, 1)  # twice: its write is two past ours, which nothing shows was built on ours
            robot.engine.put(23, 1)

    with RadioRobot(9, program=insists_on_its_own_value).holding(23, 1, timestamp=5) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "1",
                        "--wait", "5", "--tries", "3")
        writes = [m for m in robot.heard if m.op is Op.PUT and m.robot == 33]
    assert put.returncode == 1 and put.stdout == ""
    (line,) = put.stderr.splitlines()
    assert "the swarm holds value=1 timestamp=" in line and "robot=9" in line and "after 3 writes" in line
    assert [m.timestamp for m in writes] == [6, 9, 12]  # each write newer than what the robot answered


def test_put_a_robot_writes_on_top_of_at_once_was_taken_and_says_so() -> None:
    """Its program stores our write and writes the key again at once (Buzz's out-queue then sends only its
    own): the write one timestamp past ours was built on ours, so ours was taken."""
    def writes_on_top(robot: RadioRobot, msg: Message) -> None:
        robot.engine.receive(msg)
        entry = robot.engine.entry(23)
        if entry is not None and entry.robot != 9:
            robot.engine.put(23, 1)

    with RadioRobot(9, program=writes_on_top).holding(23, 1, timestamp=5) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "0.3", "--wait", "2")
        writes = [m for m in robot.heard if m.op is Op.PUT and m.robot == 33]
    assert put.returncode == 0, put.stderr
    assert put.stdout.startswith("put key=23 value=9 timestamp=6 robot=33 on ")
    assert "note: robot 9 wrote on top of it: value=1 timestamp=7 robot=9" in put.stderr
    assert [m.timestamp for m in writes] == [6]  # written once


def test_put_a_neighbour_re_broadcast_is_taken_though_a_robot_writes_on_top_while_it_closes() -> None:
    """Issue 32's Khepera run: a robot re-broadcasts our write as it stores it, and another robot's program
    writes the key again (ts + 1) a moment later, while `put` sends what it queued and closes: the write was
    taken when the re-broadcast came, and that verdict stands."""
    def stores_then_another_writes_on_top(robot: RadioRobot, msg: Message) -> None:
        robot.engine.receive(msg)  # stored: its re-broadcast goes out now
        if msg.op is Op.PUT and msg.robot == 33:
            threading.Timer(0.02, robot.say.append, (Message(Op.PUT, 23, 1, msg.timestamp + 1, 1),)).start()

    with RadioRobot(4, program=stores_then_another_writes_on_top).holding(23, 5, timestamp=10) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "0.3", "--wait", "2")
    assert put.returncode == 0, put.stderr
    assert put.stdout.startswith("put key=23 value=9 timestamp=11 robot=33 on ")


def test_put_that_loses_a_conflict_writes_again_and_then_says_who_won() -> None:
    def answers_each_write_with_a_conflicting_one(robot: RadioRobot, msg: Message) -> None:
        if msg.op is Op.PUT and msg.robot == 33:  # same timestamp, higher robot id: it wins by default
            robot.say.append(Message(Op.PUT, 23, 1, msg.timestamp, 200))

    with RadioRobot(200, program=answers_each_write_with_a_conflicting_one) as robot:
        put = run_vstig("put", "23", "9", "--on", robot.link, "--robot-id", "33", "--learn", "0",
                        "--wait", "5", "--tries", "2")
        writes = [m.timestamp for m in robot.heard if m.op is Op.PUT and m.robot == 33]
    assert put.returncode == 1 and put.stdout == ""
    assert writes == [1, 2]  # the second write is newer than the entry that won
    assert "the swarm holds value=1 timestamp=2 robot=200" in put.stderr and "after 2 writes" in put.stderr


def test_get_prints_the_newest_value_heard_within_wait_not_the_first() -> None:
    def writes_again_later(robot: RadioRobot, msg: Message) -> None:
        robot.engine.receive(msg)
        if msg.op is Op.GET and not robot.heard[:-1]:  # the first question: answer, then update soon after
            threading.Timer(0.5, robot.engine.put, (3, 777)).start()

    with RadioRobot(12, program=writes_again_later).holding(3, 500, timestamp=4) as robot:
        got = run_vstig("get", "3", "--on", robot.link, "--wait", "2")
    assert got.returncode == 0, got.stderr
    assert got.stdout.strip() == "key=3 value=777 timestamp=5 robot=12"


def test_put_on_a_radio_that_echoes_what_we_send_does_not_take_the_echo_for_an_answer() -> None:
    radio = PtyPeer()
    stop = threading.Event()
    sent: list[Message] = []
    framing = make_serial_framing("cobs8")

    def echo() -> None:
        while not stop.is_set():
            data = radio.read(0.01)
            if data:
                radio.write(data)
                sent.extend(framing.feed(data))

    echoing = threading.Thread(target=echo, daemon=True)
    echoing.start()
    try:
        put = run_vstig("put", "23", "9", "--on", f"serial:{radio.path}", "--robot-id", "33", "--learn", "0.3")
    finally:
        stop.set()
        echoing.join(timeout=5)  # before the fds close: a later pty reuses their numbers
        radio.close()
    assert put.returncode == 1 and put.stdout == ""
    assert "brings our own GETs back (robot id 33)" in put.stderr
    assert put.stderr.rstrip().endswith("(--no-confirm writes anyway)") and "confirm=False" not in put.stderr
    assert sent and all(m.op is Op.GET for m in sent)  # found while learning: nothing was written


def test_put_on_a_transmit_only_link_needs_no_confirm_and_then_writes() -> None:
    controller = PtyPeer()
    try:
        refused = run_vstig("put", "3", "1", "--on", f"kilobot-ohc:{controller.path}")
        assert refused.returncode == 2 and "--no-confirm" in refused.stderr and "'--on'" in refused.stderr
        assert controller.read(0.2) == b""
        done = run_vstig("put", "3", "1", "--on", f"kilobot-ohc:{controller.path}", "--no-confirm")
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith("put key=3 value=1 timestamp=1 robot=254 on ")
        packet = b""
        while len(packet) < 132:
            chunk = controller.read(2.0)
            assert chunk, "no packet reached the controller"
            packet += chunk
        assert packet[0] == 0x55 and packet[1] == 0x06  # FORWARDMSGSINGLE, as SPEC 6.4 says
    finally:
        controller.close()


def test_negative_and_hex_numbers_need_no_double_dash() -> None:
    with RadioRobot(12) as robot:
        negative = run_vstig("put", "3", "-5", "--on", robot.link, "--value-type", "int16")
        assert negative.returncode == 0, negative.stderr
        assert "value=-5 " in negative.stdout and robot.engine.entry(3) == (0xFFFB, 1, 254)
        hexadecimal = run_vstig("put", "0x7fff", "0x10", "--on", robot.link)
        assert hexadecimal.returncode == 0, hexadecimal.stderr
        assert hexadecimal.stdout.startswith("put key=32767 value=16 timestamp=1 ")  # echoed in decimal
        got = run_vstig("get", "0x7fff", "--on", robot.link, "--wait", "0.5")
        assert got.stdout.strip() == "key=32767 value=16 timestamp=1 robot=254"
    typo = run_vstig("put", "3", "5", "--on", "can:virtual:x", "--robot-idd", "7")
    assert typo.returncode == 2 and "No such option '--robot-idd'" in typo.stderr


@pytest.mark.parametrize(("args", "named"), [
    (["--on", "can:virtual:x", "--robot-id", "300"], "'--robot-id': 300 does not fit can:virtual:x"),
    (["--on", "can:virtual:x?id_base=0x601"], "got 0x601"),
    (["--on", "can:virtual:x"], "'KEY': 32768 is outside 0..32767"),
])
def test_put_usage_errors_name_the_input(args: list[str], named: str) -> None:
    key = "32768" if "KEY" in named else "3"
    done = run_vstig("put", key, "5", *args)
    assert done.returncode == 2 and named in done.stderr, done.stderr
    assert len([line for line in done.stderr.splitlines() if line.startswith("Error:")]) == 1


def test_get_says_when_no_neighbour_answers() -> None:
    silent = PtyPeer()
    try:
        got = run_vstig("get", "8", "--on", f"serial:{silent.path}", "--wait", "0.5")
    finally:
        silent.close()
    assert got.returncode == 1
    assert "no neighbour" in got.stderr and "key 8" in got.stderr and "Traceback" not in got.stderr
