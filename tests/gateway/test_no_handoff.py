"""The data path without hand-offs: a link's reader thread handles what it read, holding the node, with no loop
in between; what it raises still ends `run`; a closer holding the node loses no frame. Real python-can virtual buses."""

from __future__ import annotations

import threading
import time

import can
import pytest

from vstig_hw import Message, Op
from vstig_hw.framing.can import can_framing_for
from vstig_hw.gateway import Mode, Node, SwarmClosed
from vstig_hw.links import Heard, parse


def _channels() -> tuple[str, str]:
    stamp = time.monotonic_ns()
    return f"nohandoff-a-{stamp}", f"nohandoff-b-{stamp}"


def _recv_all(bus: can.BusABC, count: int, seconds: float = 5.0) -> list[can.Message]:
    frames: list[can.Message] = []
    end = time.monotonic() + seconds
    while len(frames) < count and time.monotonic() < end:
        frame = bus.recv(0.05)
        if frame is not None:
            frames.append(frame)
    return frames


@pytest.mark.parametrize("mode", [Mode.RAW, Mode.ENGINE])
def test_a_frame_crosses_on_its_reader_thread_with_no_loop_running(mode: Mode) -> None:
    a, b = _channels()
    robot, far = can.Bus(interface="virtual", channel=a), can.Bus(interface="virtual", channel=b)
    links = [parse(f"can:virtual:{channel}").build(name, robot_id=100) for name, channel in (("a", a), ("b", b))]
    node = Node(links, 100, mode=mode)
    threads: list[str] = []
    node.listen(heard=lambda heard: threads.append(threading.current_thread().name))
    put = Message(Op.PUT, 5, 55, 1, 7)
    try:
        with node:  # open, and nobody calls run or poll
            robot.send(can_framing_for(7).encode(put)[0])
            crossed = _recv_all(far, 1)
    finally:
        robot.shutdown()
        far.shutdown()
    assert [m for f in crossed for m in can_framing_for(100).feed(f)] == [put]
    assert threads == ["read-a"]  # heard, judged and sent by the thread that read it


def test_a_listener_raising_on_a_reader_thread_closes_the_node_at_once_naming_its_error() -> None:
    (a, _b) = _channels()
    robot = can.Bus(interface="virtual", channel=a)
    node = Node([parse(f"can:virtual:{a}").build("a", robot_id=100)], 100, mode=Mode.LISTEN, period=10.0)

    def broken(heard: Heard) -> None:
        raise ValueError("the capture disk is full")

    node.listen(heard=broken)
    try:
        with node:
            robot.send(can_framing_for(7).encode(Message(Op.PUT, 1, 1, 1, 7))[0])
            assert node.wait_closed(1.0)  # woken for it, not at its next tick (10 s)
            assert isinstance(node.failure, ValueError) and "disk is full" in str(node.failure)
            with pytest.raises(SwarmClosed, match="its gateway stopped: ValueError: the capture disk is full"):
                node.check_open()
    finally:
        robot.shutdown()


def test_close_from_a_listener_hands_over_what_the_other_readers_read_and_does_not_wait() -> None:
    """A listener closing the node on its reader thread (holding the node): the batch another reader read and
    waits with for the lock is handed over, not lost, and nobody waits for anybody."""
    a, b = _channels()
    robot_a, robot_b = can.Bus(interface="virtual", channel=a), can.Bus(interface="virtual", channel=b)
    links = [parse(f"can:virtual:{channel}").build(name, robot_id=100) for name, channel in (("a", a), ("b", b))]
    node = Node(links, 100, mode=Mode.LISTEN)
    heard: list[Message] = []
    sent = [Message(Op.PUT, key, key, 1, 7) for key in range(3)]
    took: list[float] = []

    def listener(h: Heard) -> None:
        heard.append(h.message)
        if h.link == "a":  # on a's reader thread, holding the node
            for msg in sent:
                robot_b.send(can_framing_for(7).encode(msg)[0])
            time.sleep(0.3)  # b's reader has read them and waits for the node
            started = time.monotonic()
            node.close()
            took.append(time.monotonic() - started)

    node.listen(heard=listener)
    try:
        node.open()
        robot_a.send(can_framing_for(7).encode(Message(Op.PUT, 99, 1, 1, 7))[0])
        deadline = time.monotonic() + 5
        while not took and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        node.close()
        robot_a.shutdown()
        robot_b.shutdown()
    read = node.stats()["b"]["rx"]  # b's reader may end a read after a frame that just arrived (CanTransport)
    assert read >= 1 and heard == [Message(Op.PUT, 99, 1, 1, 7), *sent[:read]]
    assert took and took[0] < 1.0
    assert node.stats()["b"]["in"] == read and not node.stats()["b"]["dropped_at_stop"]
