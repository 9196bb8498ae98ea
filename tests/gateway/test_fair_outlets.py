"""The fair share where it lives: outlets on real python-can virtual buses and a real pty, and the Node's engine
tagging what it sends with the source that caused it (issue 33)."""

from __future__ import annotations

import itertools
import os
import select
import time
import tty

import can
import pytest

from vstig_hw import Message, Op
from vstig_hw.engine import Outcome, Stigmergy
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Node, Outlet, SendWindow
from vstig_hw.gateway.outlet import PACE_BURST
from vstig_hw.gateway.parts import INTAKE_BURST_TICKS, Seat
from vstig_hw.gateway.writer import WRITER_HOLD
from vstig_hw.links import parse

_ids = itertools.count()
FLOODER, QUIET = 2, 0  # link indexes


def flood(count: int) -> list[Message]:
    return [Message(Op.PUT, 1000 + i, i, 1, 66) for i in range(count)]


@pytest.fixture
def bus() -> str:
    return f"fair-{os.getpid()}-{next(_ids)}"


def heard_keys(observer: can.BusABC) -> list[int]:
    framing = can_framing_for(9)
    return [msg.key for frame in iter(lambda: observer.recv(0.2), None) for msg in framing.feed(frame)]


def test_a_backlog_leaves_evenly_spaced_and_a_quiet_spell_allows_a_burst_again() -> None:
    window = SendWindow(10, 1.0)  # 10 a second; a backlog leaves one place free (the reserve): one every 1/9 s
    assert window.reserve == 1 and window.free(0.0) == 10 and window.allowance(0.0) == 9
    window.record(0.0, 9, backlog=True)  # the burst after a quiet spell, and more waiting
    assert window.allowance(0.5) == 0 and window.next_free() == 1.0  # full for the backlog until 1.0
    assert window.free(0.5) == 1 and window.next_free(sparse=True) is None  # a sparse source's place, at once
    window.record(0.5, 1, backlog=True, sparse=True)
    assert window.free(0.6) == 0 and window.next_free(sparse=True) == 1.0  # the budget is never exceeded
    assert window.allowance(1.0) == PACE_BURST  # the window reopens: a few at once, not all nine
    window.record(1.0, PACE_BURST, backlog=True)
    assert window.allowance(1.05) == 0 and window.next_free() == pytest.approx(1 + 1 / 9)
    assert window.allowance(1.12) == 1  # then one every 1/9 s
    window.record(1.12, 1, backlog=False)  # nothing waits any more
    assert window.allowance(2.5) == 9 and window.free(2.5) == 10


def test_a_window_keeps_a_sixteenth_of_its_budget_for_sparse_sources() -> None:
    assert [SendWindow(budget, 1.0).reserve for budget in (None, 1, 3, 4, 31, 32, 64, 1000)] == [0, 0, 0, 1, 1, 2, 4,
                                                                                                   62]


def test_a_quiet_sources_message_leaves_at_once_while_a_flood_waits(bus: str) -> None:
    """The flood has the window but its reserve: the quiet source's message leaves the moment it comes (at 0.5),
    not when the window reopens (at 1.0), and the flood gets the rest."""
    observer = can.Bus(interface="virtual", channel=bus)
    link = parse(f"can:virtual:{bus}").build("out", robot_id=100)
    link.open()
    outlet = Outlet(link, budget=10, period=1.0)
    try:
        outlet.push(flood(100), FLOODER)
        assert outlet.flush(0.0) == 1.0  # the first nine of the flood: a burst, the window was quiet
        outlet.push([Message(Op.PUT, 1, 1, 1, 5)], QUIET)
        assert outlet.flush(0.5) == 1.0  # the quiet one's, at once; the flood waits for the window
        outlet.push([Message(Op.PUT, 2, 1, 1, 5)], QUIET)
        assert outlet.flush(0.6) == 1.0  # served within the round: no longer sparse, it waits for its turn
        outlet.flush(1.0)
        outlet.close()
        keys = heard_keys(observer)
    finally:
        link.close()
        observer.shutdown()
    assert keys[:10] == [*range(1000, 1009), 1]
    assert keys[10:] == [1009, 2, 1010, 1011]  # the flood's turn, then the quiet source's
    assert len(outlet) == 100 - 9 - (PACE_BURST - 1)


def test_a_slow_device_holds_a_few_messages_and_the_share_decides_what_it_gets_next() -> None:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    link = parse(f"serial:{os.ttyname(slave)}?framing=cobs8").build("radio", robot_id=100)
    link.open()
    woken: list[float] = []
    outlet = Outlet(link, budget=None, period=0.1, keep_all=True, on_room=lambda: woken.append(time.monotonic()))
    framing = make_serial_framing("cobs8")
    keys: list[int] = []
    try:
        outlet.push(flood(5000), FLOODER)  # far more than a pty nobody reads takes (a few kB)
        outlet.flush(0.0)
        assert len(outlet.writer) <= WRITER_HOLD + 64  # the writer holds little; the rest wait in the lines
        waiting = len(outlet)
        assert waiting > 2000  # a pty takes ~20 kB before it stops taking more
        outlet.push([Message(Op.PUT, 1, 1, 1, 5)], QUIET)
        outlet.flush(0.0)  # no room: it waits in its line
        deadline = time.monotonic() + 10
        while 1 not in keys and time.monotonic() < deadline:  # the radio's far end starts reading
            # never a blocking read: the writer may empty itself, and its wake-up land, just after a read took all
            if select.select([master], [], [], 0.05)[0]:
                keys += [msg.key for msg in framing.feed(os.read(master, 4096))]
            if woken:
                woken.clear()
                outlet.flush(time.monotonic())
        assert woken or 1 in keys
    finally:
        outlet.close()
        link.close()
        os.close(master)
        os.close(slave)
    assert 1 in keys, "the quiet source's message never left"
    assert keys.index(1) < 5000 - waiting + WRITER_HOLD + 64 + 2  # after what the pty and writer held, at once


def test_the_engine_takes_at_most_its_intake_from_one_source(bus: str) -> None:
    """A flood from one source past its allowance (INTAKE_BURST_TICKS ticks of intake, refilled at the intake a
    tick) is dropped before the engine and counted; the next message after the refill gets in."""
    robot = can.Bus(interface="virtual", channel=bus)
    codec = can_framing_for(7)
    with Node([parse(f"can:virtual:{bus}").build("bus", robot_id=100)], 100, period=60.0, budget=2) as node:
        assert node.seat is not None and node.seat.intake == 32  # 16 ticks of a budget of 2
        burst = 32 * INTAKE_BURST_TICKS
        for i in range(burst + 80):
            robot.send(codec.encode(Message(Op.PUT, i, i, 1, 7))[0])
        deadline = time.monotonic() + 10
        while node.stats()["bus"]["in"] < burst + 80 and time.monotonic() < deadline:
            time.sleep(0.05)
        stats = node.stats()
    robot.shutdown()
    assert stats["bus"]["drop_intake"] == 80 and stats["engine"]["stored"] == burst


def _seat(intake: int, period: float) -> Seat:
    link = parse("can:virtual:unused").build("bus", robot_id=100)
    return Seat(Stigmergy(100), [link], [], None, [], intake, period)


def test_the_intake_refills_with_time_not_with_ticks() -> None:
    """As data: a source's allowance refills at `intake` a period by the batches' read times, so a backlog after a
    stall or a late tick (a loaded machine) gets in whole, and a sustained flood only at the intake's rate."""
    seat = _seat(8, 0.125)  # 64 messages a second (times below are exact in binary), bursts of INTAKE_BURST_TICKS * 8
    batch = [Message(Op.PUT, 1, 1, 1, 7)]
    burst = 8 * INTAKE_BURST_TICKS
    assert len(seat.admit(0, None, batch * burst, 1000.0)) == burst  # a backlog: all of it
    assert seat.admit(0, None, batch, 1000.0) == []  # nothing left
    assert len(seat.admit(0, None, batch * 50, 1000.25)) == 16  # a quarter second later: 16 more
    assert len(seat.admit(0, "peer", batch * 50, 1000.25)) == 50  # another source has its own
    taken = sum(len(seat.admit(0, None, batch * 5, 1000.25 + i / 64)) for i in range(1, 193))
    assert taken == 192  # a flood of 320 a second for 3 s: 64 a second got in
    assert seat.links[0].counters["drop_intake"] == 1 + 34 + 4 * 192
    assert len(seat.admit(0, None, batch * burst * 2, 1100.0)) == burst  # refilled whole, never past it
    seat.tick()  # sources idle for a whole refill are forgotten (none is)


def test_an_answer_belongs_to_the_asker_and_leaves_ahead_of_the_flood_whose_entry_it_carries(bus: str) -> None:
    """Robot B's GET is answered with an entry a flooder's PUT put in B's outlet: the answer is B's (a second place
    in B's line), so it leaves next, not behind the flood; and it leaves once."""
    flooder_bus, b_bus = f"{bus}-h", f"{bus}-b"
    flooder, robot_b = can.Bus(interface="virtual", channel=flooder_bus), can.Bus(interface="virtual", channel=b_bus)
    links = [parse(f"can:virtual:{name}").build(name, robot_id=100) for name in (flooder_bus, b_bus)]
    with Node(links, 100, period=600.0, budget=16) as node:  # 16 per 10 min a bus: none refills on a slow run
        codec = can_framing_for(66)
        with node._lock:  # the reader waits with what it read: the rest arrives as one backlog, not one by one
            for msg in flood(200):
                flooder.send(codec.encode(msg)[0])
        deadline = time.monotonic() + 10
        while node.stats()[b_bus].get("queued", 0) < 184 and time.monotonic() < deadline:
            time.sleep(0.05)
        robot_b.send(can_framing_for(5).encode(Message(Op.GET, 1150, 0, 0, 5))[0])  # B asks for key 1150
        while node.engine is not None and node.engine.counts[Outcome.ANSWERED] < 1 and time.monotonic() < deadline:
            time.sleep(0.05)
        with node._lock:
            queue = node.outlets[1].queue
            assert len(queue) == 184  # the answer is the flood's pending entry: not queued twice
            rest = queue.drain()
        heard = heard_keys(robot_b)
    flooder.shutdown()
    robot_b.shutdown()
    # B's line was empty: the answer left at once, from the window's reserve, not behind 185 of the flood
    assert heard == [*range(1000, 1015), 1150]
    assert 1150 not in [msg.key for msg in rest] and len(rest) == 184  # and it left once
