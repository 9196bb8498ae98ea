"""vstig_hw.join against robots on real links (python-can's virtual bus, a pty radio through pyserial).

The robots are `VirtualRobots`: engines in this process stepping every 10 ms, on
a bus and a pty the swarm opens like any other link. A raw python-can handle on
the same bus plays a robot we script message by message (a conflict, a flood).
"""

from __future__ import annotations

import os
import threading
import time
import tty
from collections.abc import Iterator

import can
import pytest

import vstig_hw
from vstig_hw import Entry, Message, Op, Stigmergy
from vstig_hw.api import Change, NotTaken, Swarm, SwarmClosed
from vstig_hw.api.virtual import VirtualRobots
from vstig_hw.framing.can import can_framing_for

ME = 50


def reading(keys: list[int]) -> object:
    """A robot program: GET these keys every step (so a write reaches them and they answer)."""
    def program(robot: Stigmergy, step: int) -> None:
        for key in keys:
            robot.get(key)
    return program


@pytest.fixture
def robots() -> Iterator[VirtualRobots]:
    with VirtualRobots(can_ids=[1, 2], radio_ids=[3, 4], program=reading([1])) as swarm_robots:
        yield swarm_robots


@pytest.fixture
def swarm(robots: VirtualRobots) -> Iterator[Swarm]:
    with vstig_hw.join(*robots.links, robot_id=ME, period=0.02) as joined:
        yield joined


def wait_for(condition: object, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return True
        time.sleep(0.005)
    return False


class Scripted:
    """A robot we script frame by frame, on the swarm's CAN bus."""

    def __init__(self, robots: VirtualRobots, robot_id: int) -> None:
        channel = robots.links[0].removeprefix("can:virtual:")
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.codec = can_framing_for(robot_id)
        self.id = robot_id

    def put(self, key: int, value: int, timestamp: int) -> None:
        for frame in self.codec.encode(Message(Op.PUT, key, value, timestamp, self.id)):
            self.bus.send(frame)

    def close(self) -> None:
        self.bus.shutdown()


def test_a_put_reaches_robots_on_every_link_and_their_writes_reach_us(swarm: Swarm, robots: VirtualRobots) -> None:
    written = swarm.put(1, 1500)
    assert written == Entry(1500, 1, ME)
    assert wait_for(lambda: all(robot.entry(1) == written for robot in robots.robots))
    assert swarm.get(1) == 1500 and swarm.entry(1) == written and swarm.has(1) and not swarm.has(2)
    robots.robot(3).put(7, 70)  # on the pty radio
    assert wait_for(lambda: swarm.entry(7) == Entry(70, 1, 3))
    assert sorted(swarm.keys()) == [1, 7] and swarm.size() == 2
    seen: list[tuple[int, Entry]] = []
    swarm.foreach(lambda key, entry: seen.append((key, entry)))
    assert sorted(seen) == [(1, written), (7, Entry(70, 1, 3))]


def test_a_confirmed_put_returns_the_entry_a_neighbour_took(swarm: Swarm, robots: VirtualRobots) -> None:
    taken = swarm.put(1, 42, confirm=True, timeout=2.0)
    assert taken == Entry(42, 1, ME)
    assert any(robot.entry(1) == taken for robot in robots.robots)


def test_a_confirmed_put_the_swarm_overwrites_raises_not_taken_naming_what_it_holds() -> None:
    def stubborn(robot: Stigmergy, step: int) -> None:
        for _ in range(5):  # a program that writes the key over and over: ours is always older when it arrives
            robot.put(9, 777)

    holds = r"key 9: the swarm holds value=777 timestamp=\d+ robot=5 .*after 3 writes"
    with VirtualRobots(can_ids=[5], program=stubborn) as robots, \
            vstig_hw.join(*robots.links, robot_id=ME, period=0.02) as swarm, pytest.raises(NotTaken, match=holds):
        swarm.put(9, 1, confirm=True, timeout=0.3)


def test_a_confirmed_put_nobody_hears_raises_not_taken_saying_so() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        unheard = r"no neighbour on .* took our write .* within 0.3 s; nothing was heard"
        with vstig_hw.join(f"serial:{os.ttyname(slave)}", robot_id=ME) as swarm, \
                pytest.raises(NotTaken, match=unheard):
            swarm.put(2, 5, confirm=True, timeout=0.3, tries=1)
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize(("call", "message"), [
    (lambda s: s.put(40000, 1), "key must be an integer in 0..32767, got 40000"),
    (lambda s: s.put(1, 70000), "value: 70000 is outside uint16 range"),
    (lambda s: s.put(1, "x"), "value: 'x' is not an integer"),
    (lambda s: s.get(-1), "key must be an integer in 0..32767, got -1"),
    (lambda s: s.watch([1, 99999]), "key must be an integer in 0..32767, got 99999"),
    (lambda s: s.put(1, 1, confirm=True, timeout=0), "timeout must be a positive number"),
])
def test_bad_use_is_a_clear_error_naming_the_argument(swarm: Swarm, call: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        call(swarm)  # type: ignore[operator]


def test_joining_wrongly_is_a_clear_error(robots: VirtualRobots) -> None:
    with pytest.raises(ValueError, match="links: bad link spec 'radio:x': unknown kind 'radio'"):
        vstig_hw.join("radio:x", robot_id=1)
    with pytest.raises(ValueError, match="links: link 1 is a int"):
        vstig_hw.join(5, robot_id=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="robot_id: 300 does not fit can:virtual"):
        vstig_hw.join(robots.links[0], robot_id=300)
    with pytest.raises(ValueError, match="links: join needs at least one link"):
        vstig_hw.join(robot_id=1)


def test_a_closed_swarm_says_so(robots: VirtualRobots) -> None:
    swarm = vstig_hw.join(*robots.links, robot_id=ME)
    watch = swarm.watch()
    swarm.close()
    swarm.close()  # twice is fine
    for call in (lambda: swarm.put(1, 1), lambda: swarm.get(1), lambda: swarm.entry(1), swarm.size, swarm.keys,
                 swarm.watch):
        with pytest.raises(SwarmClosed, match=f"robot {ME}'s swarm on .* is closed: it was closed"):
            call()
    assert list(watch) == []  # a watch ends with the swarm


def test_put_confirm_get_watch_and_conflict_hooks_from_several_threads_at_once(swarm: Swarm,
                                                                               robots: VirtualRobots) -> None:
    lost: list[tuple[int, Entry]] = []
    rules: list[int] = []

    @swarm.onconflict
    def larger_value(key: int, local: Entry, remote: Entry) -> Entry:
        rules.append(key)
        return remote if (remote.value, remote.robot) > (local.value, local.robot) else local

    @swarm.onconflictlost
    def gave_up(key: int, entry: Entry) -> None:
        lost.append((key, entry))
        swarm.put(key + 1000, entry.value)  # on the gateway thread: runs at once, never deadlocks

    watch = swarm.watch()
    scripted = Scripted(robots, 200)
    errors: list[BaseException] = []

    def worker(n: int) -> None:
        try:
            for i in range(10):
                key = 100 + n * 10 + i
                if i % 3 == 0:
                    assert swarm.put(key, i, confirm=True, timeout=2.0) == Entry(i, 1, ME)
                else:
                    swarm.put(key, i)
                assert swarm.get(key) == i and swarm.entry(key) == Entry(i, 1, ME)
            conflict_key = 300 + n
            swarm.put(conflict_key, 10)  # ours at timestamp 1; robot 200 writes the same timestamp, larger value
            scripted.put(conflict_key, 20, 1)
        except BaseException as error:
            errors.append(error)

    threads = [threading.Thread(target=worker, args=(n,)) for n in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    scripted.close()
    assert not errors, errors
    assert wait_for(lambda: len(lost) == 6)
    assert sorted(key for key, _ in lost) == list(range(300, 306)) and sorted(rules) == list(range(300, 306))
    assert all(entry == Entry(10, 1, ME) for _, entry in lost)
    assert all(swarm.entry(300 + n) == Entry(20, 1, 200) for n in range(6))
    assert wait_for(lambda: all(swarm.entry(1300 + n) == Entry(10, 1, ME) for n in range(6)))
    changes: dict[int, list[Change]] = {}
    while (change := watch.get(0.5)) is not None:
        changes.setdefault(change.key, []).append(change)
    assert watch.overflow == 0
    for n in range(6):
        for i in range(10):
            assert changes[100 + n * 10 + i][0] == Change(100 + n * 10 + i, None, Entry(i, 1, ME), None, ME)
        won = changes[300 + n][-1]
        assert (won.old, won.new, won.sender) == (Entry(10, 1, ME), Entry(20, 1, 200), 200)
        assert won.link == robots.links[0].removeprefix("can:virtual:")


def test_a_watch_nobody_reads_never_stalls_the_gateway(swarm: Swarm, robots: VirtualRobots) -> None:
    idle = swarm.watch(buffer=16)
    flooder = Scripted(robots, 201)
    for key in range(2000, 2500):
        flooder.put(key, key, 1)
    flooder.close()
    assert wait_for(lambda: swarm.has(2499) and swarm.size() >= 500)
    started = time.monotonic()
    assert swarm.put(1, 5) == Entry(5, 1, ME) and swarm.get(1) == 5  # the gateway still serves us, at once
    assert time.monotonic() - started < 0.5
    assert idle.overflow == 501 - 16  # every change past the buffer, counted: 500 heard + our own put
    kept = [change.key for change in iter(lambda: idle.get(0), None)]
    assert kept == [*range(2485, 2500), 1]  # the newest stayed
    assert swarm.stats()["api"]["watch_overflow"] == 485


def test_a_callback_that_puts_does_not_deadlock(swarm: Swarm, robots: VirtualRobots) -> None:
    answered = threading.Event()

    def answer(change: Change) -> None:
        if change.key == 5 and change.link is not None:  # a robot wrote it: answer under key 6, confirmed
            swarm.put(6, change.new.value + 1, confirm=True, timeout=2.0)
            answered.set()

    handle = swarm.on_change(answer, keys=[5])
    robots.robot(2).put(5, 10)
    assert answered.wait(5.0)
    assert wait_for(lambda: robots.robot(2).entry(6) == Entry(11, 1, ME))
    handle.cancel()
    assert handle.overflow == 0


def test_a_callback_that_raises_is_counted_and_the_next_change_still_comes(swarm: Swarm,
                                                                            robots: VirtualRobots) -> None:
    seen: list[int] = []

    def fragile(change: Change) -> None:
        seen.append(change.key)
        if change.key == 1:
            raise RuntimeError("boom")

    swarm.on_change(fragile)
    swarm.put(1, 1)
    swarm.put(2, 2)
    assert wait_for(lambda: seen == [1, 2])
    assert swarm.stats()["api"]["hook_error"] == 1


def test_confirm_inside_a_conflict_hook_is_refused_not_deadlocked(swarm: Swarm, robots: VirtualRobots) -> None:
    refused: list[BaseException] = []

    @swarm.onconflict
    def rule(key: int, local: Entry, remote: Entry) -> Entry:
        try:
            swarm.put(key + 1, 1, confirm=True)
        except RuntimeError as error:
            refused.append(error)
        return local

    swarm.put(400, 1)
    scripted = Scripted(robots, 202)
    scripted.put(400, 2, 1)
    scripted.close()
    assert wait_for(lambda: refused)
    assert "cannot run on it (inside onconflict or onconflictlost)" in str(refused[0])


def test_a_conflict_rule_that_returns_nonsense_never_stops_the_gateway(swarm: Swarm, robots: VirtualRobots) -> None:
    swarm.onconflict(lambda key, local, remote: "neither")  # type: ignore[arg-type,return-value]
    swarm.put(500, 1)
    scripted = Scripted(robots, 203)
    scripted.put(500, 2, 1)
    scripted.close()
    assert wait_for(lambda: swarm.entry(500) == Entry(2, 1, 203))  # the higher robot id won instead
    # Counted each time the conflict is met: the robots may re-broadcast the two writes before the swarm settles.
    assert swarm.stats()["api"]["hook_error"] >= 1
    assert swarm.put(501, 1, confirm=True) == Entry(1, 1, ME)  # and the gateway still runs


def test_close_ends_a_confirmed_put_that_waits() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    failed: list[BaseException] = []
    try:
        swarm = vstig_hw.join(f"serial:{os.ttyname(slave)}", robot_id=ME)

        def waiting() -> None:
            try:
                swarm.put(1, 1, confirm=True, timeout=30)
            except BaseException as error:
                failed.append(error)

        thread = threading.Thread(target=waiting)
        thread.start()
        time.sleep(0.2)
        started = time.monotonic()
        swarm.close()
        thread.join(5)
        assert time.monotonic() - started < 2
        assert len(failed) == 1 and isinstance(failed[0], SwarmClosed)
        assert "is closed: it was closed" in str(failed[0])
    finally:
        os.close(master)
        os.close(slave)


def test_what_was_put_before_close_still_goes_out() -> None:
    channel = f"drain-{os.getpid()}-{time.monotonic_ns()}"
    neighbour = can.Bus(interface="virtual", channel=channel)
    codec = can_framing_for(9)
    swarm = vstig_hw.join(f"can:virtual:{channel}", robot_id=ME, budget=1, period=0.1, refresh=False)
    for key in range(600, 605):
        swarm.put(key, key)
    swarm.close()  # the budget lets one message out per period: four still queued
    heard = set()
    while (frame := neighbour.recv(0.2)) is not None:
        heard |= {msg.key for msg in codec.feed(frame) if msg.robot == ME}
    neighbour.shutdown()
    assert set(range(600, 605)) <= heard
