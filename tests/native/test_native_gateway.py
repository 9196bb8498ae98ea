"""The compiled delivery against the pure-Python Node, on random traffic (hypothesis): two Nodes over the same kind
of links get the same reads, ticks and program calls, and must write the same units to every device and end with
the same counters, tables and queues.

The links are in memory (a transport that keeps what it is given and can refuse it, so the writers' queues and the
fair share's lines fill) and the clock is the test's: the pure Node delivers through `Delivery.arrive` and
`Outbound.spread` at the test's time, the compiled one through `Path.deliver` at the same time. What only real
devices show (the compiled path reading a pty or a SocketCAN socket itself, writing straight to it) is tested with
them: the rest of tests/native, and every gateway and CLI suite, which `make test` runs on both paths.
"""

from __future__ import annotations

import functools
import random
import threading
import time
from types import ModuleType
from typing import Any

import can
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from traffic import EXAMPLES, can_frames, messages, noisy

from vstig_hw import Entry, Message, Op, Stigmergy, encode
from vstig_hw.counters import Counters
from vstig_hw.framing import make_serial_framing
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.framing.mavlink import MavlinkFraming
from vstig_hw.framing.xbee import api_frame, receive_packet
from vstig_hw.gateway import assembly as assembly_module
from vstig_hw.gateway import compiled as compiled_module
from vstig_hw.gateway.fairshare import FairFifo, FairQueue
from vstig_hw.gateway.guard import Guard
from vstig_hw.gateway.node import Listening, Mode, Node
from vstig_hw.gateway.outlet import RAW_QUEUE_LIMIT, Outlet, SendWindow
from vstig_hw.gateway.parts import Seat
from vstig_hw.gateway.writer import TX_QUEUE_LIMIT, LinkWriter
from vstig_hw.links.link import Heard, Link
from vstig_hw.transports.base import Transport


@EXAMPLES
# the budgets where the reserve starts and grows are drawn as often as all others: a twin that is off by one
# there is caught every run (a C window keeping no reserve at a budget of 4 once went unseen)
@given(budget=st.none() | st.sampled_from([3, 4, 5, 31, 32, 33]) | st.integers(1, 40),
       period=st.sampled_from([0.1, 1.0, 0.3]),
       calls=st.lists(st.tuples(st.integers(0, 40), st.integers(0, 9), st.booleans(), st.booleans()), max_size=60))
def test_window_equals_send_window(compiled: ModuleType, budget: int | None, period: float,
                                   calls: list[tuple[int, int, bool, bool]]) -> None:
    """Backlogs paced and sparse sources' messages from the reserve: the same answers."""
    python, c = SendWindow(budget, period), compiled.Window(budget, period)
    now = 0.0
    for step, count, backlog, sparse in calls:
        now += step / 100  # whole hundredths and their sums: the same floats on both sides
        assert c.allowance(now) == python.allowance(now)
        assert c.free(now) == python.free(now)
        python.record(now, count, backlog, sparse)
        c.record(now, count, backlog, sparse)
        assert c.next_free() == python.next_free()
        assert c.next_free(sparse=True) == python.next_free(sparse=True)
    assert (c.budget, c.period, c.reserve) == (python.budget, python.period, python.reserve)


class MemoryTransport(Transport[Any]):
    """A device in memory: keeps every unit it takes. While `full` it takes nothing: `write_nowait` hands the unit
    back, and the writer thread's `write` waits (`blocked`) until it is not full any more."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.counters = Counters()
        self.taken: list[Any] = []
        self.blocked = False
        self._full = False
        self._room = threading.Condition()

    @property
    def full(self) -> bool:
        return self._full

    @full.setter
    def full(self, full: bool) -> None:
        with self._room:
            self._full = full
            if not full:  # a writer waiting in `write` is held no longer: settling waits for it to finish
                self.blocked = False
            self._room.notify_all()

    def open(self) -> None:
        pass

    def close(self) -> None:
        self.full = False

    def read(self, timeout: float) -> list[Any]:
        return []

    def write(self, unit: Any) -> None:
        with self._room:
            self.blocked = True
            while self._full:
                self._room.wait()
            self.blocked = False
            self.taken.append(unit)

    def write_nowait(self, unit: Any) -> Any:
        with self._room:
            if self._full:
                return unit
            self.taken.append(unit)
            return None

    @property
    def connected(self) -> bool:
        return True


def _settled(node: Node) -> None:
    """Until every writer thread is done or waits in a full device: both Nodes are then at the same point."""
    deadline = time.monotonic() + 10
    for link, outlet in zip(node.links, node.outlets, strict=True):
        transport: Any = link.transport
        while not (outlet.writer.idle or transport.blocked):
            assert time.monotonic() < deadline, "a writer did not settle"
            time.sleep(0.001)


# (link name, framing, one broadcast domain)
LINKS = [("radio", "cobs8", False), ("bus", "can", True), ("words", "epuck4", False), ("modules", "xbee", False),
         ("kilo", "kilobot", False), ("drones", "mavlink", False)]
LINK = st.integers(0, len(LINKS) - 1)


def _links() -> list[Link[Any]]:
    built = []
    for name, framing, one_domain in LINKS:
        made: Any = CanFraming(CanIdScheme(), sender=9) if framing == "can" else make_serial_framing(framing)
        built.append(Link(name, MemoryTransport(name), made, one_domain=one_domain))
    return built


def _node(compiled: bool, mode: Mode, budget: int | None, guard: Guard | None) -> Node:
    with pytest.MonkeyPatch.context() as patch:
        if not compiled:
            patch.setattr(assembly_module, "compiled_for", lambda relays, links: None)
        node = Node(_links(), 9, mode=mode, period=1.0, budget=budget, guard=guard)
    assert (node._delivery.path is not None) == compiled
    return node


def _units(rng: random.Random, framing: str, sent: list[Message], frames: list[can.Message]) -> list[Any]:
    if framing == "can":
        encoder = CanFraming(CanIdScheme(), sender=rng.choice([3, 4]))
        return [frame for m in sent for frame in encoder.encode(m)] + frames
    if framing == "xbee":  # Receive Packets from two modules (the sender a Python guard is told), mostly one a unit
        units = [api_frame(receive_packet(rng.choice([0x0013A20040A1B2C3, 0x7E]), encode(m))) for m in sent]
        if rng.random() < 0.8:
            return units
    elif framing == "mavlink":  # TUNNELs from two drones, mostly one frame a unit
        units = [MavlinkFraming(rng.choice([3, 200]), 1).encode(m)[0] for m in sent]
        if rng.random() < 0.8:
            return units
    else:
        units = [unit for m in sent for unit in make_serial_framing(framing).encode(m)]
    stream = noisy(rng, units)
    cuts = sorted(rng.sample(range(1, len(stream)), min(3, len(stream) - 1))) if len(stream) > 1 else []
    return [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]


def _state(node: Node) -> dict[str, Any]:
    def unit(u: Any) -> Any:
        return (u.arbitration_id, u.is_fd, bytes(u.data)) if isinstance(u, can.Message) else bytes(u)

    engine = node.engine
    return {
        "written": [[unit(u) for u in link.transport.taken] for link in node.links],  # type: ignore[attr-defined]
        "stats": node.stats(),
        "outlets": [(len(o), len(o.writer)) for o in node.outlets],
        "table": None if engine is None else list(engine.entries()),
        "counts": None if engine is None else engine.counts,
    }


calls = st.one_of(
    st.tuples(st.just("heard"), LINK, st.integers(0, 2**32), st.lists(messages, max_size=6),
              st.lists(can_frames(), max_size=2)),
    st.tuples(st.just("time"), st.integers(0, 300)),
    st.tuples(st.just("full"), LINK, st.booleans()),
    st.tuples(st.just("put"), st.integers(0, 3), st.integers(0, 9)),
    st.tuples(st.just("get"), st.integers(0, 3)),
    st.tuples(st.just("ask"), st.integers(0, 3)),
    st.tuples(st.just("tick")),
)


def _flood(count: int) -> list[Message]:
    """More PUTs at once than a source's intake takes with a budget of 1 (its burst: 160)."""
    return [Message(Op.PUT, i % 40, i, 1 + i, 2) for i in range(count)]


def _run(node: Node, call: tuple[Any, ...], clock: list[float]) -> None:
    name, *args = call
    t, now = 1_700_000_000.0 + clock[0], clock[0]  # wall clock for the guard, monotonic for the outlets
    if name == "time":
        clock[0] += args[0] / 100
    elif name == "full":
        node.links[args[0]].transport.full = args[1]  # type: ignore[attr-defined]
    elif name in ("heard", "flood"):
        index, seed, sent, frames = args if name == "heard" else (*args[:2], _flood(args[2]), [])
        units = _units(random.Random(seed), LINKS[index][1], sent, frames)
        with node._lock:
            if node._delivery.path is None or not node._delivery.path.deliver(index, t, units, now):
                assert node._delivery.path is None or node._listeners.heard, \
                    "only a `heard` listener takes the Python delivery"
                node._delivery.arrive(index, t, units)
                node._outbound.spread(now, 1 << index)
    elif name == "tick":
        with node._lock:
            node._tick()
            node._outbound.spread(now)
    elif node.mode is Mode.ENGINE:
        with node._lock:
            getattr(node.seat, name)(*args)
            node._outbound.spread(now)


def _guard(kind: str) -> Guard | None:
    if kind == "none":
        return None
    return Guard(max_jump=3) if kind == "jump" else Guard(max_jump=3, rate=5.0)  # rate: stays Python


def _close(node: Node) -> None:
    for link, outlet in zip(node.links, node.outlets, strict=True):
        link.transport.close()
        outlet.writer.close(1.0)


@EXAMPLES
@given(mode=st.sampled_from([Mode.ENGINE, Mode.RAW]), budget=st.none() | st.integers(1, 6),
       guard=st.sampled_from(["none", "jump", "python"]), script=st.lists(calls, max_size=40))
def test_the_compiled_delivery_equals_the_python_node(compiled: ModuleType, mode: Mode, budget: int | None,
                                                      guard: str, script: list[tuple[Any, ...]]) -> None:
    nodes = [_node(False, mode, budget, _guard(guard)), _node(True, mode, budget, _guard(guard))]
    clocks = [[0.0], [0.0]]
    for call in script:
        for node, clock in zip(nodes, clocks, strict=True):
            _run(node, call, clock)
            _settled(node)
        pure, compiled_state = (_state(node) for node in nodes)
        assert compiled_state == pure, call
    for node in nodes:
        _close(node)


def test_a_pure_node_is_built_when_vstig_pure_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(compiled_module, "native", None)
    node = Node(_links(), 9)
    assert node._delivery.path is None and type(node.engine).__module__ == "vstig_hw.engine"


def _outlets(compiled: ModuleType, keep_all: bool, budget: int | None) -> tuple[Outlet, Outlet]:
    links = [Link("out", MemoryTransport("out"), make_serial_framing("cobs8")) for _ in range(2)]
    python = Outlet(links[0], budget, 1.0, keep_all=keep_all)
    c_writer = LinkWriter(links[1], TX_QUEUE_LIMIT)
    queue = FairFifo(RAW_QUEUE_LIMIT) if keep_all else FairQueue()
    c = compiled_module.CompiledOutlet(links[1], c_writer, compiled.Window(budget, 1.0), queue, keep_all=keep_all,
                                       encoder=compiled.Encoder("cobs8"))  # the Node's own
    return python, c


outlet_calls = st.one_of(
    st.tuples(st.just("push"), st.lists(messages, max_size=5), st.sampled_from([-1, 0, 1, 2]),
              st.sampled_from([None, None, "peer-a", "peer-b"])),
    st.tuples(st.just("flush"), st.integers(0, 150)),
    st.tuples(st.just("full"), st.booleans()),
)


_TWO = [Message(Op.PUT, 1, 1, 1, 1), Message(Op.PUT, 2, 1, 1, 1)]


@EXAMPLES
@example(keep_all=True, budget=None, script=[("push", _TWO, 0, None), ("push", _TWO, 1, None), ("flush", 0)])
@given(keep_all=st.booleans(), budget=st.none() | st.integers(1, 5), script=st.lists(outlet_calls, max_size=50))
def test_outlet_equals_the_python_outlet(compiled: ModuleType, keep_all: bool, budget: int | None,
                                         script: list[tuple[Any, ...]]) -> None:
    """Pushes from several sources (links and a link's peers), held or queued in their lines, flushed through a
    window and a writer whose device fills up: the same units, counters and lengths."""
    outlets = _outlets(compiled, keep_all, budget)
    now = 0.0
    try:
        for name, *args in script:
            if name == "flush":
                now += args[0] / 100
            results = []
            for outlet in outlets:
                transport: Any = outlet.link.transport
                if name == "push":
                    results.append(outlet.push(list(args[0]), args[1], args[2]))
                elif name == "flush":
                    results.append(outlet.flush(now))
                else:
                    results.append(None)
                    transport.full = args[0]
                deadline = time.monotonic() + 10
                while not (outlet.writer.idle or transport.blocked):
                    assert time.monotonic() < deadline, "the writer did not settle"
                    time.sleep(0.001)
            assert results[0] == results[1], name
            python, c = ([bytes(u) for u in o.link.transport.taken] for o in outlets)  # type: ignore[attr-defined]
            assert c == python
            python_state, c_state = ((len(o), len(o.writer), o.link.counters, o.handed) for o in outlets)
            assert c_state == python_state
    finally:
        for outlet in outlets:
            outlet.link.transport.close()
            outlet.close()
    assert outlets[1].link.counters == outlets[0].link.counters


def _tell(told: list[tuple[Any, ...]], *change: Any) -> None:
    told.append(change)


seat_calls = st.one_of(
    st.tuples(st.just("take"), st.integers(0, 2), st.lists(messages, max_size=30),
              st.sampled_from([None, None, "peer-a", "peer-b"]), st.sampled_from([0, 0, 1]) | st.integers(-5, 40)),
    st.tuples(st.just("tick")),
    st.tuples(st.just("put"), st.integers(0, 3), st.integers(0, 9)),
    st.tuples(st.just("get"), st.integers(0, 3)),
    st.tuples(st.just("ask"), st.integers(0, 3)),
    st.tuples(st.just("queue_out")),
)


_MANY = [Message(Op.PUT, key, 1, 1, 1) for key in range(12)]


@EXAMPLES
@example(intake=1, period=0.1, listening=False, script=[("take", 0, _MANY, None, 0), ("take", 0, _MANY, "peer-a", 0)])
@given(intake=st.none() | st.integers(1, 10), period=st.sampled_from([0.1, 0.25, 1.0]), listening=st.booleans(),
       script=st.lists(seat_calls, max_size=40))
def test_seat_equals_the_python_seat(compiled: ModuleType, intake: int | None, period: float, listening: bool,
                                     script: list[tuple[Any, ...]]) -> None:
    """The engine's intake per source (a link, or one of its peers; a token bucket refilled by the batches' read
    times, which step back now and then), what a one-domain link heard kept off it, change listeners told of every
    change: the same queues, counters and calls."""
    sides = []
    for compiled_side in (False, True):
        links = _links()
        outlets = [Outlet(link, None, 1.0) for link in links] if not compiled_side else \
            [compiled.Outlet(link, LinkWriter(link, TX_QUEUE_LIMIT), compiled.Window(None, 1.0), FairQueue(),
                             encoder=None) for link in links]
        engine = Stigmergy(9) if not compiled_side else compiled.Engine(9)
        told: list[tuple[Any, ...]] = []
        listeners = (functools.partial(_tell, told),) if listening else ()
        seat = (compiled.Seat if compiled_side else Seat)(engine, links, outlets, None, listeners, intake, period)
        sides.append((seat, outlets, told))
    t = 1_700_000_000.0
    try:
        for name, *args in script:
            results = []
            if name == "take":
                t += args[3] / 64  # whole 64ths of a second and their sums: the same floats on both sides
            for seat, outlets, _ in sides:
                if name == "take":
                    index, batch, sub, _step = args
                    admitted = seat.admit(index, sub, list(batch), t) if intake is not None else list(batch)
                    results.append((admitted, seat.take(index, admitted, 7, sub)))
                else:
                    results.append(getattr(seat, name)(*args))
                for outlet in outlets:
                    outlet.flush(0.0)
            assert results[1] == results[0], name
            python, c = ([[len(o), o.link.counters, [bytes(u) for u in o.link.transport.taken]] for o in outlets]
                         for _, outlets, _ in sides)
            assert c == python
            assert sides[1][2] == sides[0][2]
            assert list(sides[1][0].engine.entries()) == list(sides[0][0].engine.entries())
    finally:
        for _, outlets, _ in sides:
            for outlet in outlets:
                outlet.close()


# -- listeners: the compiled delivery tells `messages` and `change` listeners itself --------------------------------

def _listen(node: Node, log: list[tuple[Any, ...]], kind: str, number: int) -> Listening:
    """A listener of `kind` writing every call into `log`, tagged with `number` (its place among the listeners)."""
    def messages(link: str, t: float, sender: int | None, batch: list[Message]) -> None:
        log.append(("messages", number, link, t, sender, [(type(m), *m) for m in batch]))
        if kind == "once":  # cancels itself: the rest of this batch still reaches it, as the others
            listening.cancel()

    def change(key: int, old: Any, new: Any, link: str | None, sender: int | None) -> None:
        log.append(("change", number, key, old, new, link, sender))

    def refused(heard: Heard, reason: str) -> None:
        log.append(("refused", number, type(heard), type(heard.message), *heard.message, heard.link, heard.t,
                    heard.sender, reason))

    def heard(heard: Heard) -> None:  # wants every `Heard`: the Python delivery's alone
        log.append(("heard", number, heard))

    listening: Listening = node.listen(
        messages=messages if kind in ("messages", "once", "both", "live") else None,
        change=change if kind in ("change", "both") else None, refused=refused if kind in ("refused", "live") else None,
        heard=heard if kind == "heard" else None)
    return listening


listener_calls = st.one_of(
    calls,
    st.tuples(st.just("flood"), LINK, st.integers(0, 2**32), st.integers(150, 400)),
    st.tuples(st.just("listen"), st.sampled_from(["messages", "change", "both", "once", "refused", "live", "heard"])),
    st.tuples(st.just("cancel"), st.integers(0, 5)),
)


@EXAMPLES
@example(mode=Mode.ENGINE, budget=1, guard="jump", script=[
    ("listen", "both"), ("listen", "live"),
    ("heard", 1, 7, [Message(Op.PUT, 1, 5, 1, 3), Message(Op.PUT, 1, 50, 2, 3)], []),
    ("flood", 0, 3, 300), ("listen", "once"), ("flood", 1, 4, 200), ("cancel", 0), ("listen", "change"),
    ("heard", 3, 5, [Message(Op.PUT, 2, 5, 1, 3)], [])])
@given(mode=st.sampled_from([Mode.ENGINE, Mode.RAW]), budget=st.none() | st.just(1) | st.integers(1, 6),
       guard=st.sampled_from(["none", "jump", "python"]), script=st.lists(listener_calls, max_size=40))
def test_the_compiled_delivery_tells_listeners_as_the_python_node(
        compiled: ModuleType, mode: Mode, budget: int | None, guard: str, script: list[tuple[Any, ...]]) -> None:
    """`messages`, `refused` and `change` listeners added and cancelled as traffic flows (floods past the engine's
    intake, a guard refusing some, a listener that cancels itself, a `heard` listener that sends the batches to the
    Python delivery while it listens): the same calls, in the same order, with the same senders, `Message`s and
    `Heard`s."""
    nodes = [_node(False, mode, budget, _guard(guard)), _node(True, mode, budget, _guard(guard))]
    clocks: list[list[float]] = [[0.0], [0.0]]
    logs: list[list[tuple[Any, ...]]] = [[], []]
    listenings: list[list[Listening]] = [[], []]
    for step, call in enumerate(script):
        for node, clock, log, mine in zip(nodes, clocks, logs, listenings, strict=True):
            if call[0] == "listen":
                mine.append(_listen(node, log, call[1], step))
            elif call[0] == "cancel":
                if mine:
                    mine.pop(call[1] % len(mine)).cancel()
            else:
                _run(node, call, clock)
            _settled(node)
        assert logs[1] == logs[0], call
        pure, compiled_state = (_state(node) for node in nodes)
        assert compiled_state == pure, call
    for node in nodes:
        _close(node)


def test_the_compiled_delivery_tells_each_link_s_sender(compiled: ModuleType) -> None:
    """The sender a `messages` listener is told: a CAN frame's node (from its ID), an XBee module's 64-bit source,
    a drone's sysid << 8 | compid, none on the other serial links; both deliveries, through `Delivery.take` as a
    reader thread calls it."""
    told: list[list[tuple[str, int | None]]] = [[], []]
    for node, log in zip([_node(False, Mode.ENGINE, None, None), _node(True, Mode.ENGINE, None, None)], told,
                         strict=True):
        node.listen(messages=lambda link, t, sender, batch, log=log: log.append((link, sender)))  # type: ignore[misc]
        for index, (_name, framing, _) in enumerate(LINKS):
            sent = Message(Op.PUT, 1, index, 1 + index, 2)
            units: list[Any] = CanFraming(CanIdScheme(), sender=4).encode(sent) if framing == "can" else \
                [api_frame(receive_packet(0x0013A20040A1B2C3, encode(sent)))] if framing == "xbee" else \
                MavlinkFraming(3, 1).encode(sent) if framing == "mavlink" else \
                list(make_serial_framing(framing).encode(sent))
            node._delivery.take(index, 1_700_000_000.0, units)
        assert node._state.failure is None
    assert told[1] == told[0]
    senders = dict(told[0])
    assert senders["radio"] is senders["words"] is senders["kilo"] is None
    assert (senders["bus"], senders["modules"], senders["drones"]) == (4, 0x0013A20040A1B2C3, 3 << 8 | 1)


@pytest.mark.parametrize("kind", ["messages", "change", "refused"])
def test_a_listener_that_raises_ends_the_loop_on_either_delivery(compiled: ModuleType, kind: str) -> None:
    """A listener raising on its second call: the batch stops where Python's stops (what was taken stays taken,
    what was refused stays counted, nothing is sent for it, its messages are not counted in), and the loop's next
    step raises the same error."""
    refusing = kind == "refused"  # key 1 jumps from timestamp 1 to 100 and 200: refused twice
    sent = [Message(Op.PUT, 1, 7, ts, 2) for ts in (1, 100, 200, 2)] if refusing else \
        [Message(Op.PUT, key, 7, 1, 2) for key in (1, 2, 3)]
    outcomes = []
    for node in (_node(False, Mode.ENGINE, None, Guard(max_jump=3) if refusing else None),
                 _node(True, Mode.ENGINE, None, Guard(max_jump=3) if refusing else None)):
        calls: list[Any] = []

        def listener(*args: Any, calls: list[Any] = calls) -> None:
            calls.append(args)
            if len(calls) == 2:
                raise RuntimeError(f"listener broke at {args[0]!r}")

        node.listen(**{kind: listener})
        units = [unit for m in sent for unit in make_serial_framing("cobs8").encode(m)]
        node._delivery.take(0, 1_700_000_000.0, units)
        _settled(node)
        with pytest.raises(RuntimeError) as raised:
            node._loop._step(0)
        outcomes.append((str(raised.value), calls, _state(node)))
        node._loop._step(0)  # raised once: the loop goes on
        _close(node)
    assert outcomes[1] == outcomes[0]
    assert len(outcomes[0][1]) == 2 and outcomes[0][2]["table"] == [(1, Entry(7, 1, 2))] + \
        ([(2, Entry(7, 1, 2))] if kind == "change" else [])
    assert outcomes[0][2]["stats"]["radio"]["drop_jump"] == (2 if refusing else 0)
