"""Our slcan reader against python-can's own `slcanBus`, the reference, on the same bytes.

The slcan line protocol's receive side (`SlcanLines`, `parse_line`) must make the same
Messages of the same lines as python-can, whatever chunks the bytes come in, and skip
(and count) what python-can raises on. Lines are fed to python-can's driver through
pyserial's real `loop://` port (one line, one `recv`), and whole streams through real
ptys to both drivers side by side.
"""

from __future__ import annotations

import os
import time
import tty
from collections.abc import Iterator

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vstig_hw.counters import Counters
from vstig_hw.transports.slcan import SlcanBus, SlcanLines, frame_line, is_answer, parse_line

FD_LENGTHS = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64]


@st.composite
def frames(draw: st.DrawFn) -> can.Message:
    extended = draw(st.booleans())
    can_id = draw(st.integers(0, 0x1FFFFFFF if extended else 0x7FF))
    kind = draw(st.sampled_from(["data", "remote", "fd", "fd_brs"]))
    if kind == "remote":
        return can.Message(arbitration_id=can_id, is_extended_id=extended, is_remote_frame=True,
                           dlc=draw(st.integers(0, 8)))
    length = draw(st.sampled_from(FD_LENGTHS)) if kind.startswith("fd") else draw(st.integers(0, 8))
    return can.Message(arbitration_id=can_id, is_extended_id=extended, data=draw(st.binary(min_size=length,
                       max_size=length)), is_fd=kind.startswith("fd"), bitrate_switch=kind == "fd_brs")


ascii_noise = st.text(alphabet=st.characters(min_codepoint=0, max_codepoint=127), max_size=40).map(str.encode)
any_noise = st.binary(max_size=40)
streams = st.lists(st.one_of(frames(), ascii_noise), max_size=30)


def same(a: can.Message | None, b: can.Message | None) -> bool:
    if a is None or b is None:
        return a is b
    return a.equals(b, timestamp_delta=None)


class Reference:
    """python-can's slcanBus on pyserial's loop:// port: one line in, its result out (Message, None or raised)."""

    def __init__(self) -> None:
        self.bus = can.Bus(interface="slcan", channel="loop://", sleep_after_open=0)
        self.port = self.bus.serialPortOrig
        self.take(b"")  # the "O\r" python-can wrote to open the adapter comes back first: not a frame

    def take(self, line: bytes) -> can.Message | Exception | None:
        self.port.write(line)
        try:
            return self.bus.recv(0)  # type: ignore[no-any-return]
        except Exception as exc:  # python-can raises on lines it cannot parse
            return exc

    def close(self) -> None:
        self.bus.shutdown()


@pytest.fixture(scope="module")
def reference() -> Iterator[Reference]:
    ref = Reference()
    yield ref
    ref.close()


def stream_of(segments: list[can.Message | bytes]) -> tuple[bytes, list[tuple[int, can.Message]]]:
    """The bytes, and each frame that stays a line of its own (what came before it ended a line) by line number."""
    data, intact = b"", []
    for segment in segments:
        whole = not data or data[-1:] in (b"\r", b"\x07")
        if isinstance(segment, can.Message):
            if whole:
                intact.append((data.count(b"\r") + data.count(b"\x07"), segment))
            data += frame_line(segment)
        else:
            data += segment
    return data, intact


def lines_of(data: bytes, cuts: list[int]) -> list[bytes]:
    """`data` fed to SlcanLines in the pieces `cuts` makes."""
    reader, lines, last = SlcanLines(), [], 0
    for cut in [*sorted(c % (len(data) + 1) for c in cuts), len(data)]:
        lines += reader.feed(data[last:cut])
        last = cut
    return lines


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(segments=streams, cuts=st.lists(st.integers(0, 10_000), max_size=8))
def test_every_line_reads_as_python_can_reads_it(reference: Reference, segments: list[can.Message | bytes],
                                                 cuts: list[int]) -> None:
    data, intact = stream_of(segments)
    lines = lines_of(data, cuts)
    assert lines == lines_of(data, [])  # chunks do not matter
    assert b"".join(lines) == data[:len(b"".join(lines))]  # nothing but the unterminated tail is held back
    results = [reference.take(line) for line in lines]
    ours = [parse_line(line) for line in lines]
    for line, mine, theirs in zip(lines, ours, results, strict=True):
        if mine is not None:  # what we read, python-can reads the same
            assert isinstance(theirs, can.Message) and same(mine, theirs), (line, mine, theirs)
    for index, sent in intact:  # a frame line of its own: both read it, as it was sent
        assert same(ours[index], sent) and isinstance(results[index], can.Message), (lines[index], results[index])
        assert same(results[index], sent)


@settings(max_examples=200, deadline=None)
@given(segments=st.lists(st.one_of(frames(), any_noise), max_size=30), cuts=st.lists(st.integers(0, 10_000),
                                                                                      max_size=8))
def test_noise_of_any_bytes_costs_only_its_own_lines(segments: list[can.Message | bytes], cuts: list[int]) -> None:
    """Bytes that are not ASCII (python-can's reader raises on them from then on) cost no frame of a line of its own."""
    data, intact = stream_of(segments)
    got = [parse_line(line) for line in lines_of(data, cuts)]
    for index, sent in intact:
        assert same(got[index], sent)


def test_a_line_that_never_ends_is_cut_off_and_counted_once() -> None:
    reader = SlcanLines()
    assert reader.feed(b"x" * 100) == []
    assert reader.feed(b"y" * 100) == [] and reader.overlong == 1
    assert reader.feed(b"z" * 1000) == [] and reader.overlong == 1  # the same line still
    assert reader.feed(b"zz\rt1230\r") == [b"t1230\r"] and reader.overlong == 1  # its end is dropped


@pytest.mark.parametrize("line", [b"t1230\r", b"T1FFFFFFF0\r", b"t7FF8" + b"00" * 8 + b"\r", b"r1238\r",
                                  b"d123F" + b"AB" * 64 + b"\r", b"B000000019" + b"FF" * 12 + b"\r"])
def test_well_formed_lines_read_and_write_back(reference: Reference, line: bytes) -> None:
    mine = parse_line(line)
    assert mine is not None and same(mine, reference.take(line))  # type: ignore[arg-type]
    assert frame_line(mine) == line


def test_a_lawicel_timestamp_after_the_data_is_allowed(reference: Reference) -> None:
    line = b"t123211227A3F\r"  # 2 bytes, then 0x7A3F ms
    mine = parse_line(line)
    assert mine is not None and same(mine, reference.take(line))  # type: ignore[arg-type]
    assert bytes(mine.data) == b"\x11\x22"


@pytest.mark.parametrize("line", [b"t12381122\r", b"t1239" + b"00" * 12 + b"\r", b"t800" + b"0\r",
                                  b"T200000000\r", b"t12G0\r", b"t1230 \r", b"t0x10\r"])
def test_lines_python_can_half_reads_are_garbage_here(reference: Reference, line: bytes) -> None:
    """python-can makes a Message of some malformed lines (a DLC of 8 with one byte, an 11-bit ID of 0x800...)
    or raises; we count them all as garbage."""
    assert parse_line(line) is None


@settings(max_examples=300, deadline=None)
@given(msg=frames())
def test_we_write_the_line_python_can_writes(msg: can.Message) -> None:
    bus = can.Bus(interface="slcan", channel="loop://", sleep_after_open=0)
    try:
        port = bus.serialPortOrig
        port.read(port.in_waiting)  # "O\r"
        bus.send(msg)
        port.timeout = 5
        assert frame_line(msg) == port.read_until(b"\r")
    finally:
        bus.shutdown()


# -- whole streams through real ptys, to both drivers --------------------------------

def _pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def _drain(bus: can.BusABC, quiet: float = 0.1) -> list[can.Message | Exception]:
    got: list[can.Message | Exception] = []
    last = time.monotonic()
    while time.monotonic() - last < quiet:
        try:
            msg = bus.recv(0.02)
        except can.CanError as exc:
            got.append(exc)
            continue
        except (ValueError, IndexError) as exc:
            got.append(exc)
            last = time.monotonic()
            continue
        if msg is not None:
            got.append(msg)
            last = time.monotonic()
    return got


@settings(max_examples=15, deadline=None)
@given(segments=st.lists(st.one_of(frames(), ascii_noise), min_size=1, max_size=40))
def test_both_drivers_on_real_ptys_hear_the_same_frames(segments: list[can.Message | bytes]) -> None:
    data, intact = stream_of(segments)
    (m1, s1, p1), (m2, s2, p2) = _pty(), _pty()
    counters = Counters()
    theirs_bus = can.Bus(interface="slcan", channel=p1, sleep_after_open=0)
    ours_bus = SlcanBus(p2, counters=counters)
    try:
        for master in (m1, m2):
            os.read(master, 64)  # the "O\r" each wrote
            os.write(master, data + b"\r")  # a last terminator: every line ends
        theirs = [m for m in _drain(theirs_bus) if isinstance(m, can.Message)]
        ours = _drain(ours_bus)
        assert all(isinstance(m, can.Message) for m in ours)  # noise never raises here
        assert len(ours) <= len(theirs)
        it = iter(theirs)  # ours are python-can's, in order, less the malformed lines it half-reads
        assert all(any(same(m, t) for t in it) for m in ours)  # type: ignore[arg-type]
        for _, sent in intact:
            assert any(same(m, sent) for m in ours)  # type: ignore[arg-type]
    finally:
        theirs_bus.shutdown()
        ours_bus.shutdown()
        for fd in (m1, s1, m2, s2):
            os.close(fd)


@pytest.mark.parametrize(("line", "answer"), [(b"\r", True), (b"\x07", True), (b"z\r", True), (b"Z\r", True),
                                              (b"V1013\r", True), (b"NA123\r", True), (b"F00\r", True),
                                              (b"zz\r", False), (b"V10\r", False), (b"Fxy\r", False),
                                              (b"hello\r", False), (b"O\r", False)])
def test_an_adapters_answers_are_not_noise(line: bytes, answer: bool) -> None:
    assert is_answer(line) is answer


def test_noise_is_counted_once_per_line() -> None:
    """Through a real pty: each line of noise is one rx_garbage, an overlong one too, answers none."""
    master, slave, path = _pty()
    counters = Counters()
    bus = SlcanBus(path, counters=counters)
    try:
        os.read(master, 64)
        os.write(master, b"hello\rz\r" + b"n" * 500 + b"\rt1230\r\x07V1013\r")
        got = [m for m in _drain(bus) if isinstance(m, can.Message)]
        assert [m.arbitration_id for m in got] == [0x123]
        assert counters["rx_garbage"] == 2
    finally:
        bus.shutdown()
        os.close(master)
        os.close(slave)
