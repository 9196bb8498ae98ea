"""The compiled relay over real ptys reads what it shares with Python as Python does (issue 46's speed work).

The delivery reads the declared slots (a transport's CompiledHandle, the Node's DeliveryState) at their offsets and
the clocks without a call into Python: a handle whose class redefines a slot is still read through that class, and
the times the C stamps compare with Python's own clocks.
"""

from __future__ import annotations

import os
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any

import pytest

from vstig_hw import Message, Op
from vstig_hw.framing import make_serial_framing
from vstig_hw.gateway import Mode, Node
from vstig_hw.links import parse
from vstig_hw.transports import base
from vstig_hw.transports.base import CompiledHandle

COBS8 = make_serial_framing("cobs8")


@contextmanager
def two_radios() -> Iterator[tuple[int, int, list[Any]]]:
    """Two raw ptys: (A's far end, B's far end, [link on A, link on B])."""
    (a_master, a_slave), (b_master, b_slave) = os.openpty(), os.openpty()
    fds = (a_master, a_slave, b_master, b_slave)
    for fd in fds:
        tty.setraw(fd)
    os.set_blocking(b_master, False)
    links = [parse(f"serial:{os.ttyname(fd)}?framing=cobs8").build(name, robot_id=200)
             for name, fd in (("a", a_slave), ("b", b_slave))]
    try:
        yield a_master, b_master, links
    finally:
        for fd in fds:
            os.close(fd)


def arrived(fd: int, count: int, seconds: float = 5.0) -> list[Message]:
    """The messages that reach pty end `fd` until `count` came or `seconds` passed."""
    framing = make_serial_framing("cobs8")
    got: list[Message] = []
    end = time.monotonic() + seconds
    while len(got) < count and time.monotonic() < end:
        try:
            got.extend(framing.feed(os.read(fd, 4096)))
        except BlockingIOError:
            time.sleep(0.005)
    return got


def test_the_compiled_relay_stamps_reads_with_pythons_wall_clock(compiled: ModuleType) -> None:
    """Each batch's read time (told to `delivered` and `messages` listeners) lies between Python's time.time()
    before the write and after the relayed frame arrived."""
    stamps: list[tuple[str, float]] = []
    windows: list[tuple[float, float]] = []
    with two_radios() as (a, b, links), Node(links, 200, mode=Mode.RAW, budget=None) as node:
        assert node.compiled
        node.listen(delivered=lambda t: stamps.append(("delivered", t)),
                    messages=lambda _link, t, _sender, _msgs: stamps.append(("messages", t)))
        for key in range(5):
            before = time.time()
            os.write(a, COBS8.encode(Message(Op.PUT, key, 1, 1, 7))[0])
            assert [m.key for m in arrived(b, 1)] == [key]
            windows.append((before, time.time()))
    assert [kind for kind, _t in stamps] == ["messages", "delivered"] * 5
    for (before, after), (_, told), (_, delivered) in zip(windows, stamps[::2], stamps[1::2], strict=True):
        assert before <= told == delivered <= after


def test_a_window_held_back_reopens_on_pythons_monotonic_clock(compiled: ModuleType) -> None:
    """A budget of 4 messages a period holds most of a burst back: the delivery says when its window reopens
    (`retry_at`, set in C) on the clock the loop waits by, time.monotonic(), and the loop sends the rest then."""
    with two_radios() as (a, b, links), Node(links, 200, mode=Mode.RAW, budget=4, period=0.5) as node:
        assert node.compiled
        before = time.monotonic()
        os.write(a, b"".join(COBS8.encode(Message(Op.PUT, key, 1, 1, 7))[0] for key in range(12)))
        first = arrived(b, 12, seconds=0.2)  # what the window let out at once; the rest waits for it
        retry_at = node._state.retry_at  # what the compiled delivery set, under the Node's lock
        assert 0 < len(first) < 12
        assert retry_at is not None and before < retry_at <= time.monotonic() + 0.5
        rest = arrived(b, 12 - len(first), seconds=5.0)
    assert sorted(m.key for m in first + rest) == list(range(12))


FD_SLOT: Any = vars(CompiledHandle)["fd"]  # the base's slot (its member descriptor)


class WatchedHandle(CompiledHandle[Any]):
    """A handle whose class redefines `fd` (a property over the base's slot), counting the reads through it."""

    __slots__ = ("fd_reads",)

    def __init__(self, preamble: bytes = b"") -> None:
        self.fd_reads = 0
        super().__init__(preamble)

    @property
    def fd(self) -> int | None:
        self.fd_reads += 1
        value: int | None = FD_SLOT.__get__(self)
        return value

    @fd.setter
    def fd(self, value: int | None) -> None:
        FD_SLOT.__set__(self, value)


def test_a_handle_whose_class_redefines_a_slot_is_read_through_its_class(compiled: ModuleType,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The offsets are the declared class's: an object of another class (here one whose `fd` is a property) is
    read by name, as Python reads it, and still relays."""
    monkeypatch.setattr(base, "CompiledHandle", WatchedHandle)
    with two_radios() as (a, b, links), Node(links, 200, mode=Mode.RAW, budget=None) as node:
        assert node.compiled
        handles = [link.transport.compiled_handle() for link in links]
        assert all(type(handle) is WatchedHandle for handle in handles)
        reads_before = [handle.fd_reads for handle in handles]
        for key in range(3):  # one at a time: three reads, three writes
            os.write(a, COBS8.encode(Message(Op.PUT, key, 1, 1, 7))[0])
            assert [m.key for m in arrived(b, 1)] == [key]
        reads_after = [handle.fd_reads for handle in handles]
    assert reads_after[0] >= reads_before[0] + 3  # A's reads: one a read at least
    assert reads_after[1] >= reads_before[1] + 3  # B's writes: one a write at least
