"""The gateway Node on real python-can virtual buses: engine, raw and listen modes."""

from __future__ import annotations

import gc
import itertools
import sys
import threading
import time
from collections.abc import Callable

import can
import pytest
from waiting import wait_until

from vstig_hw import Message, Op, Stigmergy
from vstig_hw.counters import Counters
from vstig_hw.engine import Outcome
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Mode, Node, Outlet, SendWindow, favour_latency
from vstig_hw.links import Heard, Link, parse
from vstig_hw.transports.base import Transport

_ids = itertools.count()


def bus_link(channel: str, name: str | None = None, robot_id: int = 100, *, echo: bool = False) -> Link[can.Message]:
    return parse(f"can:virtual:{channel}{'?echo=1' if echo else ''}").build(name or channel, robot_id=robot_id)


class BusRobot:
    """A robot on a virtual bus: an engine, a bus handle, and one control step at a time."""

    def __init__(self, robot_id: int, channel: str) -> None:
        self.engine = Stigmergy(robot_id)
        self.framing = can_framing_for(robot_id)
        self.bus = can.Bus(interface="virtual", channel=channel)

    def step(self) -> None:
        while (frame := self.bus.recv(0)) is not None:
            for msg in self.framing.feed(frame):
                self.engine.receive(msg)
        for msg in self.engine.drain():
            for frame in self.framing.encode(msg):
                self.bus.send(frame)

    def close(self) -> None:
        self.bus.shutdown()


@pytest.fixture
def channels() -> tuple[str, str]:
    n = next(_ids)
    return f"gw-a-{n}", f"gw-b-{n}"


def run_until(node: Node, done: Callable[[], bool], robots: list[BusRobot] = (), deadline: float = 10.0) -> None:  # type: ignore[assignment]
    end = time.monotonic() + deadline
    while not done():
        assert time.monotonic() < end, "timed out"
        for robot in robots:
            robot.step()
        time.sleep(0.02)


def test_engine_mode_carries_a_put_across_buses(channels: tuple[str, str]) -> None:
    a, b = channels
    left, right = BusRobot(5, a), BusRobot(9, b)
    with Node([bus_link(a), bus_link(b)], robot_id=100) as node:
        left.engine.put(3, 1234)
        run_until(node, lambda: right.engine.entry(3) is not None, [left, right])
        assert right.engine.entry(3) == (1234, 1, 5)
        assert node.engine is not None and node.engine.entry(3) == (1234, 1, 5)
        node.put(4, 77)  # and the PC's own writes reach both sides
        run_until(node, lambda: left.engine.has(4) and right.engine.has(4), [left, right])
        stats = node.stats()
        assert stats[a]["in"] >= 1 and stats[b]["out"] >= 2
    left.close()
    right.close()


def test_raw_mode_relays_every_frame_without_an_engine(channels: tuple[str, str]) -> None:
    a, b = channels
    tap = can.Bus(interface="virtual", channel=a)
    far = can.Bus(interface="virtual", channel=b)
    framing = can_framing_for(7)
    sent = [Message(Op.PUT, 1, v, 1, 7) for v in range(20)]  # same key and timestamp: an engine would keep one
    with Node([bus_link(a), bus_link(b)], mode=Mode.RAW, budget=None) as node:
        assert node.engine is None
        for msg in sent:
            for frame in framing.encode(msg):
                tap.send(frame)
        got: list[Message] = []

        def all_arrived() -> bool:
            while (frame := far.recv(0)) is not None:
                got.extend(framing.feed(frame))
            return len(got) >= len(sent)

        run_until(node, all_arrived)
    assert got == sent
    tap.shutdown()
    far.shutdown()


def test_news_crosses_to_the_other_link_before_the_echo_goes_back(channels: tuple[str, str]) -> None:
    a, b = channels
    buses = {a: can.Bus(interface="virtual", channel=a), b: can.Bus(interface="virtual", channel=b)}
    framing = can_framing_for(7)
    # echo=1: as radios whose robots may not all hear each other, the re-broadcast goes back too
    with Node([bus_link(a, echo=True), bus_link(b, echo=True)], robot_id=100) as node:
        for key, (source, other) in enumerate([(a, b), (b, a)]):  # from the first link, then from the second
            buses[source].send(framing.encode(Message(Op.PUT, key, 5, 1, 7))[0])
            heard: dict[str, can.Message] = {}

            def both_heard(heard: dict[str, can.Message] = heard) -> bool:
                for name, bus in buses.items():
                    while (frame := bus.recv(0)) is not None:
                        heard[name] = frame
                return len(heard) == 2

            run_until(node, both_heard)
            # the virtual bus stamps each frame when it is sent: the crossing went first
            assert heard[other].timestamp < heard[source].timestamp, f"PUT from {source}"
    for bus in buses.values():
        bus.shutdown()


def _drain(bus: can.BusABC) -> list[can.Message]:
    frames = []
    while (frame := bus.recv(0)) is not None:
        frames.append(frame)
    return frames


def test_a_put_heard_on_a_bus_crosses_but_is_not_echoed_onto_that_bus(channels: tuple[str, str]) -> None:
    a, b = channels
    robot, on_a, on_b = (can.Bus(interface="virtual", channel=c) for c in (a, a, b))
    put = Message(Op.PUT, 4, 77, 1, 7)
    with Node([bus_link(a), bus_link(b)], robot_id=100) as node:
        robot.send(can_framing_for(7).encode(put)[0])
        crossed: list[can.Message] = []
        run_until(node, lambda: bool(crossed.extend(_drain(on_b)) or crossed))
        time.sleep(0.3)  # ticks in which an echo would have gone out
        stats = node.stats()
    decode = can_framing_for(100).feed
    assert [m for f in crossed for m in decode(f)] == [put]
    assert [m for f in _drain(on_a) for m in decode(f)] == [put]  # the robot's own frame, and no copy of ours
    assert stats[a]["not_echoed"] == 1 and stats[a]["out"] == 0
    for bus in (robot, on_a, on_b):
        bus.shutdown()


def test_the_gateways_own_get_of_another_key_in_that_poll_does_not_undo_it(channels: tuple[str, str]) -> None:
    """A program reading key 9 every tick (as `RoundRobinGet` does) while the PUT of key 4 arrives."""
    a, b = channels
    robot, on_a, on_b = (can.Bus(interface="virtual", channel=c) for c in (a, a, b))
    put = Message(Op.PUT, 4, 77, 1, 7)
    with Node([bus_link(a), bus_link(b)], robot_id=100, period=1e-6) as node:  # every poll ticks
        node.put(9, 1)
        node.listen(tick=lambda n: n.get(9) and None)
        robot.send(can_framing_for(7).encode(put)[0])
        crossed: list[can.Message] = []
        wait_until(lambda: put in [m for f in crossed for m in ours(f)], step=lambda: crossed.extend(_drain(on_b)))
        time.sleep(0.1)  # many more ticks, each with its GET of key 9
    assert put not in [m for f in _drain(on_a) if can_framing_for(100).sender_of(f) == 100 for m in ours(f)]
    for bus in (robot, on_a, on_b):
        bus.shutdown()


def ours(frame: can.Message) -> list[Message]:
    return can_framing_for(100).feed(frame)


def test_a_stale_get_on_the_bus_a_put_came_from_is_answered_there(channels: tuple[str, str]) -> None:
    """Robot 8 missed robot 7's PUT: its GET with the older entry, heard in the same poll, still gets the answer."""
    a, b = channels
    robot7, robot8, on_a = (can.Bus(interface="virtual", channel=a) for _ in range(3))
    newer = Message(Op.PUT, 4, 77, 2, 7)
    node = Node([bus_link(a), bus_link(b)], robot_id=100)
    with node:
        robot7.send(can_framing_for(7).encode(newer)[0])
        robot8.send(can_framing_for(8).encode(Message(Op.GET, 4, 60, 1, 8))[0])
        time.sleep(0.2)  # both wait in the arrival queue: one poll hears them (the PUT's echo note, then the GET)
        answers: list[Message] = []
        ours = can_framing_for(100)

        def answered() -> bool:
            answers.extend(m for f in _drain(on_a) if ours.sender_of(f) == 100 for m in ours.feed(f))
            return newer in answers

        run_until(node, answered)
    assert node.engine is not None and node.engine.counts[Outcome.ANSWERED] >= 1
    for bus in (robot7, robot8, on_a):
        bus.shutdown()


def test_listen_mode_never_transmits_and_reports_what_it_heard(channels: tuple[str, str]) -> None:
    a, _ = channels
    tap = can.Bus(interface="virtual", channel=a)
    observer = can.Bus(interface="virtual", channel=a)
    heard: list[Heard] = []
    node = Node([bus_link(a)], mode=Mode.LISTEN)
    node.listen(heard=heard.append)
    with node:
        for frame in can_framing_for(42).encode(Message(Op.GET, 2, 0, 0, 42)):
            tap.send(frame)
        run_until(node, lambda: bool(heard))
        time.sleep(0.3)  # a few ticks in which a robot would have answered or re-broadcast
    assert heard[0].sender == 42 and heard[0].message.op is Op.GET
    assert observer.recv(0) is not None  # the GET itself
    assert observer.recv(0) is None  # and nothing from the sniffer
    with pytest.raises(RuntimeError):
        node.put(1, 1)
    tap.shutdown()
    observer.shutdown()


def test_status_has_the_engine_outcomes_and_a_counting_listener_still_never_transmits(
        channels: tuple[str, str]) -> None:
    a, b = channels
    tap = can.Bus(interface="virtual", channel=a)
    observer = can.Bus(interface="virtual", channel=a)
    bridge = Node([bus_link(b)], robot_id=100)
    listener = Node([bus_link(a)], mode=Mode.LISTEN, count_outcomes=True)
    assert "engine" not in Node([bus_link(a, "plain")], mode=Mode.LISTEN).stats()  # record pays for no engine
    with listener:
        for msg in (Message(Op.PUT, 2, 7, 3, 42), Message(Op.GET, 2, 0, 0, 43), Message(Op.GET, 9, 0, 0, 43)):
            for frame in can_framing_for(42).encode(msg):
                tap.send(frame)
        run_until(listener, lambda: listener.stats()["engine"].total() == 3)
        time.sleep(0.3)  # ticks in which a robot would answer the GET and re-broadcast the PUT
        assert listener.summary().endswith("engine: answered=1 stored=1 unknown=1")
        with pytest.raises(RuntimeError):
            listener.put(1, 1)
    assert [observer.recv(0) is not None for _ in range(4)] == [True, True, True, False]  # only the tap's frames
    with bridge:
        bridge.put(1, 1)
        assert "engine: -" in bridge.summary()  # no message heard yet: no outcome
    tap.shutdown()
    observer.shutdown()


def test_budget_holds_each_link_to_k_messages_per_tick(channels: tuple[str, str]) -> None:
    a, _ = channels
    observer = can.Bus(interface="virtual", channel=a)
    with Node([bus_link(a)], robot_id=1, period=0.2, budget=5) as node:
        for key in range(12):
            node.put(key, key)
        arrivals: list[float] = []

        def drained() -> bool:
            while observer.recv(0) is not None:
                arrivals.append(time.monotonic())
            return len(arrivals) >= 12

        run_until(node, drained)
    first = arrivals[0]
    assert sum(t - first < 0.15 for t in arrivals) == 5  # the first window sends exactly the budget
    observer.shutdown()


def test_send_window_slides() -> None:
    window = SendWindow(3, 1.0)
    assert window.allowance(0.0) == 3
    window.record(0.0, 2)
    window.record(0.5, 1)
    assert window.allowance(0.9) == 0 and window.next_free() == 1.0
    assert window.allowance(1.0) == 2 and window.allowance(1.5) == 3
    with pytest.raises(ValueError, match="budget"):
        SendWindow(0, 1.0)


def test_per_link_queue_keeps_the_newest_message_per_key(channels: tuple[str, str]) -> None:
    a, _ = channels
    observer = can.Bus(interface="virtual", channel=a)
    framing = can_framing_for(7)
    with Node([bus_link(a)], robot_id=1, period=10.0, budget=1) as node:
        node.put(1, 10)  # goes out at once: the window is open
        node.put(1, 11)  # waits: the window is full for 10 s
        node.put(1, 12)  # replaces 11 in the link's queue
        assert node.stats()[a]["queued"] == 1
    frames = [observer.recv(0) for _ in range(3)]
    values = [framing.feed(f)[0].value for f in frames if f is not None]
    assert values == [10]
    observer.shutdown()


class BrokenTransport(Transport[can.Message]):
    """A transport that breaks its promise never to raise (nothing real fails on cue like this)."""

    name = "broken"
    connected = True  # type: ignore[assignment]  # a plain attribute for the abstract property

    def __init__(self) -> None:
        self.counters = Counters()

    def open(self) -> None: ...

    def close(self) -> None: ...

    def read(self, timeout: float) -> list[can.Message]:
        return []

    def write(self, unit: can.Message) -> None:
        raise OSError("device exploded")


def test_a_raising_transport_costs_its_batch_not_the_loop() -> None:
    link: Link[can.Message] = Link("broken", BrokenTransport(), can_framing_for(1))
    outlet = Outlet(link, budget=10, period=1.0)
    for key in range(4):
        outlet.push([Message(Op.PUT, key, key, 1, 1)])
    assert outlet.flush(0.0) is None  # everything left the queue, none of it the device
    outlet.close()  # the link's writer thread met the exploding device
    assert link.counters["drop_write_error"] == 4 and link.counters["out"] == 0 and not len(outlet)


def test_favour_latency_shortens_gil_turns_and_freezes_the_startup_heap() -> None:
    before = sys.getswitchinterval()
    try:
        favour_latency()
        assert sys.getswitchinterval() == pytest.approx(0.0005)
        assert gc.get_freeze_count() > 1000  # at least the imported modules' objects
    finally:
        gc.unfreeze()
        sys.setswitchinterval(before)


def test_node_rejects_bad_wiring() -> None:
    with pytest.raises(ValueError, match="at least one link"):
        Node([])
    with pytest.raises(ValueError, match="differ"):
        Node([bus_link("x", "same"), bus_link("y", "same")])
    with pytest.raises(ValueError, match="raw bridge"):
        Node([bus_link("x")], mode=Mode.RAW)



def test_drain_ends_once_what_was_held_back_left_though_the_swarm_keeps_talking(channels: tuple[str, str]) -> None:
    """A robot on bus a rewrites three keys every 2 ms; the node passes them to bus b at one message a step:
    b's queue never empties, yet `drain` returns once the three it held when asked have gone out."""
    a, b = channels
    talker = can.Bus(interface="virtual", channel=a)
    framing = can_framing_for(7)
    running = True

    def talk() -> None:
        stamp = 0
        while running:
            stamp += 1
            for key in (1, 2, 3):
                talker.send(framing.encode(Message(Op.PUT, key, stamp & 0xFFFF, stamp, 7))[0])
            time.sleep(0.002)

    thread = threading.Thread(target=talk, daemon=True)
    handled: list[float] = []  # when the node handled a batch (on its reader's thread)
    with Node([bus_link(a), bus_link(b)], robot_id=100, period=0.1, budget=1) as node:
        node.listen(delivered=lambda _t: handled.append(time.monotonic()))
        thread.start()
        wait_until(lambda: node.stats()[b].get("queued", 0) >= 3, 5)
        started = time.monotonic()
        drained = node.drain(3.0)
        ended = time.monotonic()
        took = ended - started
        running = False
        thread.join(2)
    talker.shutdown()
    assert drained and took < 1.0, took  # three messages at one a step, not the 3 s timeout
    assert any(started + took / 3 < at < started + took * 2 / 3 for at in handled)  # heard while it drained
