"""Capture files: our serial format, candump lines, rotation, and the replayer's timing rule."""

from __future__ import annotations

import contextlib
import gzip
import io
import json
import os
import sys
import threading
import time
from pathlib import Path

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vstig_hw.capture import candump
from vstig_hw.capture.decoded import decode_file
from vstig_hw.capture.fastlog import chunk_to_jsonl
from vstig_hw.capture.files import RotatingCapture, rotated_name
from vstig_hw.capture.records import CaptureError, Damage, Record, read_capture
from vstig_hw.capture.replay import replay
from vstig_hw.capture.serial_log import HEADER, parse_line


def test_serial_capture_round_trip(tmp_path: Path) -> None:
    path = str(tmp_path / "radio.cap")
    records = [Record(1700000000.25 + i / 8, "radio0", "cobs8", bytes([i, 0, 255]), "rx") for i in range(5)]
    writer = RotatingCapture(path, "serial")
    for record in records:
        writer.write(record)
    writer.close()
    text = Path(path).read_text()
    assert text.startswith(HEADER + "\n") and "(1700000000.250000) radio0 cobs8 rx 0000ff" in text
    back = list(read_capture(path))
    assert [(r.link, r.framing, r.unit, r.direction) for r in back] == [
        (r.link, r.framing, r.unit, r.direction) for r in records]
    assert [round(r.t, 6) for r in back] == [round(r.t, 6) for r in records]


def test_serial_capture_bad_line_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.cap"
    path.write_text(f"{HEADER}\n(1.000000) r cobs8 rx 00\n(2.0) r cobs8 sideways 00\n(3.000000) r cobs8 rx 0\n")
    with pytest.raises(CaptureError, match=r"bad.cap:3: not a serial capture line"):
        list(read_capture(str(path)))
    damage = Damage(skip=True)
    assert len(list(read_capture(str(path), damage))) == 1
    assert [e.line for e in damage.first] == [3, 4] and damage.count == 2


def test_damage_counts_every_bad_line_keeps_the_first_few_and_a_fresh_one_starts_at_zero(tmp_path: Path) -> None:
    path = tmp_path / "many.cap"
    path.write_text(f"{HEADER}\n" + "junk\n" * 250 + "(1.000000) r cobs8 rx 00\n")
    damage = Damage(skip=True, keep=100)
    assert len(list(read_capture(str(path), damage))) == 1
    assert damage.count == 250 and [e.line for e in damage.first] == list(range(2, 102))
    again = damage.fresh()
    assert (again.skip, again.keep, again.count, again.first) == (True, 100, 0, [])
    with pytest.raises(CaptureError, match=r"many.cap:2: "):
        list(read_capture(str(path)))  # the default raises at the first


@given(st.text(max_size=80))
def test_serial_line_parser_only_raises_capture_error(line: str) -> None:
    try:
        parse_line("f", 1, line)
    except CaptureError as error:
        assert str(error).startswith("f:1: ")


def test_candump_lines_classic_fd_remote_extended() -> None:
    frame = candump.parse_line("f", 1, "(1700000000.500000) can0 601#8001000200030004\n")
    assert frame is not None and frame.arbitration_id == 0x601 and not frame.is_extended_id
    assert bytes(frame.data) == bytes.fromhex("8001000200030004") and frame.channel == "can0"
    fd = candump.parse_line("f", 2, "(1.0) vcan0 18000005##1" + "00" * 16)
    assert fd is not None and fd.is_fd and fd.bitrate_switch and fd.is_extended_id and len(fd.data) == 16
    remote = candump.parse_line("f", 3, "(1.0) can0 123#R")
    assert remote is not None and remote.is_remote_frame
    assert candump.parse_line("f", 4, "   \n") is None


@pytest.mark.parametrize("line", ["1.0 can0 600#00", "(x) can0 600#00", "(1.0) can0 6000#00", "(1.0) can0 600#0",
                                  "(1.0) can0 600#" + "00" * 9, "(1.0) can0", "(1.0) can0 60G#00"])
def test_candump_bad_lines(line: str) -> None:
    with pytest.raises(CaptureError, match=r"^log:7: not a candump line"):
        candump.parse_line("log", 7, line)


@given(st.text(max_size=80))
def test_candump_parser_only_raises_capture_error(line: str) -> None:
    with contextlib.suppress(CaptureError):
        candump.parse_line("f", 1, line)


def test_candump_capture_written_by_python_can_reads_back(tmp_path: Path) -> None:
    path = str(tmp_path / "bus.log")
    writer = RotatingCapture(path, "can")
    for i in range(3):
        frame = can.Message(timestamp=1700000000 + i, arbitration_id=0x600 + i, data=bytes(range(i, i + 8)),
                            is_extended_id=False)
        writer.write(Record(frame.timestamp, "lab", "can", frame))
    writer.close()
    back = list(read_capture(path))
    assert [r.unit.arbitration_id for r in back] == [0x600, 0x601, 0x602] and back[0].link == "lab"
    assert bytes(back[2].unit.data) == bytes(range(2, 10))


@pytest.mark.parametrize("ext", [".asc", ".blf", ".csv", ".pcap"])
def test_python_can_formats_by_extension(tmp_path: Path, ext: str) -> None:
    path = str(tmp_path / f"bus{ext}")
    writer = RotatingCapture(path, "can")
    frames = [can.Message(timestamp=1700000000.5 + i, arbitration_id=0x600 | i, data=bytes([i] * 8),
                          is_extended_id=False) for i in range(4)]
    for frame in frames:
        writer.write(Record(frame.timestamp, "lab", "can", frame))
    writer.close()
    back = [r.unit for r in read_capture(path)]
    assert [(f.arbitration_id, bytes(f.data)) for f in back] == [(f.arbitration_id, bytes(f.data)) for f in frames]


def test_rotation_by_size_keeps_every_record(tmp_path: Path) -> None:
    path = str(tmp_path / "big.cap")
    writer = RotatingCapture(path, "serial", max_bytes=2000)
    for i in range(1000):
        writer.write(Record(1.0 + i, "r", "cobs8", bytes([i & 0xFF] * 10)))
    writer.close()
    assert len(writer.files) > 3 and writer.files[1] == rotated_name(path, 1) == str(tmp_path / "big_001.cap")
    total = [r for f in writer.files for r in read_capture(f)]
    assert len(total) == 1000 and total[-1].unit == bytes([999 & 0xFF] * 10)


@pytest.mark.parametrize("ext", [".log", ".asc", ".cap"])
def test_a_small_size_limit_rotates_at_the_record_that_reaches_it(tmp_path: Path, ext: str) -> None:
    """Twenty records of about 40 bytes under a 300-byte limit: a file ends at the first record that reaches
    the limit, not some records later."""
    path = str(tmp_path / f"small{ext}")
    medium = "serial" if ext == ".cap" else "can"
    writer = RotatingCapture(path, medium, max_bytes=300)
    sizes = []
    for i in range(20):
        before = writer.files[-1]
        if medium == "can":
            frame = can.Message(timestamp=1700000000.5 + i, arbitration_id=0x600, data=bytes([i] * 8),
                                is_extended_id=False)
            writer.write(Record(frame.timestamp, "lab", "can", frame))
        else:
            writer.write(Record(1.0 + i, "r", "cobs8", bytes([i] * 10)))
        if writer.files[-1] != before:
            sizes.append(os.path.getsize(before))
    writer.close()
    assert len(writer.files) >= 2, writer.files
    assert all(300 <= size < 300 + 80 for size in sizes), sizes  # one record (under 80 bytes) past at most
    assert sum(1 for f in writer.files for _ in read_capture(f)) == 20


def test_unknown_capture_type_is_named(tmp_path: Path) -> None:
    path = tmp_path / "x.bin"
    path.write_bytes(b"\x01\x02")
    with pytest.raises(CaptureError, match=r"unknown capture type '\.bin'"):
        list(read_capture(str(path)))


@pytest.mark.parametrize(("content", "says"), [
    (b"not gzip at all", "cannot read"),
    (gzip.compress(b"(1.000000) can0 600#00\n" * 50)[:30], r"cut short .*: read all \d+ frames before the cut")],
    ids=["garbage", "cut-short"])
def test_unreadable_gzip_capture_is_a_capture_error_naming_the_file(tmp_path: Path, content: bytes,
                                                                     says: str) -> None:
    path = tmp_path / "bad.log.gz"
    path.write_bytes(content)
    with pytest.raises(CaptureError, match=rf"bad\.log\.gz: {says}"):
        list(read_capture(str(path)))


def test_replay_keeps_absolute_deadlines() -> None:
    clock = [0.0]
    sent: list[float] = []

    def fake_clock() -> float:
        clock[0] += 0.0001  # every clock read costs 0.1 ms of "time"
        return clock[0]

    records = [Record(100.0 + i * 0.01, "r", "cobs8", b"") for i in range(200)]
    result = replay(records, lambda r: sent.append(clock[0]), speed=2.0, clock=fake_clock,
                    keep_lateness=True)
    assert result.frames == 200 and abs(result.logged - 199 * 0.005) < 1e-9
    # per-frame overhead never accumulates: the last frame leaves on its deadline, not 200 overheads late
    assert max(result.lateness) < 0.0005
    assert abs(result.took - result.logged) < 0.001


def _classify(can_id: int) -> int | None:
    return (can_id >> 8) & 1 if can_id & 0x600 == 0x600 else None


def test_fast_candump_path_matches_the_line_parser() -> None:
    lines = [f"({1700000000 + i}.{i * 7 % 1000000:06d}) can0 {0x600 | (i % 2) << 8 | i % 50:03X}#"
             f"{(i % 2) << 15 | i % 3000:04X}{i * 13 % 65536:04X}{i % 65535 + 1:04X}{i % 50:04X}\n" for i in range(300)]
    lines.append("(0000000012.000100) can0 200#0001000200030004\n")  # an unknown id: dropped
    lines.append("(0000000012.000200) can0 700#0001000200030004\n")  # a PUT under a GET id: op mismatch
    drops: dict[str, int] = {}
    fast = chunk_to_jsonl("".join(lines).encode(), _classify, drops)
    assert fast is not None and drops == {"unknown_id": 1, "op_mismatch": 1}
    rows = [json.loads(line) for line in fast.decode().splitlines()]
    assert len(rows) == 300
    for row, line in zip(rows, lines, strict=False):
        frame = candump.parse_line("f", 1, line)
        assert frame is not None
        word0, value, ts, robot = (int.from_bytes(frame.data[i:i + 2], "big") for i in range(0, 8, 2))
        assert row == {"t": pytest.approx(frame.timestamp, abs=1e-6), "link": "can0", "can_id": frame.arbitration_id,
                       "op": "GET" if word0 >> 15 else "PUT", "key": word0 & 0x7FFF, "value": value,
                       "timestamp": ts, "robot": robot, "sender": frame.arbitration_id & 0xFF}


def test_fast_path_declines_mixed_or_bad_chunks() -> None:
    good = "(1700000000.000000) can0 600#0001000200030004\n"
    assert chunk_to_jsonl((good + "(1700000000.000000) can0 600#00010002000300\n").encode(), _classify, {}) is None
    assert chunk_to_jsonl((good + "(1700000000.000000) can0 600#000100020003000Z\n").encode(), _classify, {}) is None
    assert chunk_to_jsonl(good.replace("600#", "600 ").encode(), _classify, {}) is None
    assert chunk_to_jsonl(good.encode() * 3, _classify, {}) is not None


def test_line_by_line_fallback_numbers_lines_as_the_file_does(tmp_path: Path) -> None:
    good = "(1700000000.000000) can0 600#0001000200030004\n"
    path = tmp_path / "mixed.log"
    path.write_text(good + "junk\x0cwith a form feed\n" + good + "bad line\n")
    errors: dict[str, list[int | None]] = {}
    for fmt in ("jsonl", "text"):  # jsonl takes the chunked fast path, text the per-record reader
        damage = Damage(skip=True)
        decode_file(str(path), io.StringIO(), fmt, damage=damage)
        errors[fmt] = [error.line for error in damage.first]
    assert errors["jsonl"] == errors["text"] == [2, 4]


def test_a_stop_during_a_long_gap_ends_the_replay_at_once_and_sends_nothing_more() -> None:
    records = [Record(100.0, "r", "cobs8", b"a"), Record(120.0, "r", "cobs8", b"b")]
    sent: list[bytes] = []
    stop = threading.Event()
    threading.Timer(0.3, stop.set).start()
    began, cpu = time.monotonic(), time.process_time()
    result = replay(records, lambda r: sent.append(r.unit), stop=stop)
    assert sent == [b"a"] and result.stopped and result.frames == 1
    assert time.monotonic() - began < 10.0  # not the 20 s gap
    assert time.process_time() - cpu < 2.0  # slept: no core spun through the gap


def test_skip_gaps_shortens_long_waits_and_ignore_timestamps_drops_them() -> None:
    records = [Record(t, "r", "cobs8", b"") for t in (0.0, 0.01, 50.0, 50.01, 900.0)]
    began = time.monotonic()
    result = replay(records, lambda r: None, skip_gaps=0.05)
    assert result.frames == 5 and time.monotonic() - began < 10.0
    assert result.skipped == pytest.approx((50.0 - 0.01 - 0.05) + (900.0 - 50.01 - 0.05))
    result = replay(records, lambda r: None, ignore_timestamps=True)
    assert result.frames == 5 and result.skipped == pytest.approx(900.0) and result.took < 10.0
    with pytest.raises(ValueError, match="skip_gaps"):
        replay(records, lambda r: None, skip_gaps=-1)


def test_fast_path_with_every_frame_dropped_renders_nothing() -> None:
    """Found by `make fuzz`: a chunk of foreign IDs only used to raise IndexError in _render."""
    drops: dict[str, int] = {}
    chunk = "".join(f"(1700000000.00000{i}) can0 {ident}#0001000200030004\n" for i, ident in enumerate(("599", "407")))
    assert chunk_to_jsonl(chunk.encode(), _classify, drops) == b""
    assert drops == {"unknown_id": 2}


def test_replay_sleeps_short_by_the_overshoot_it_measures_and_spins_only_the_rest() -> None:
    now = [0.0]
    reads = [0]

    def clock() -> float:
        reads[0] += 1
        now[0] += 1e-6  # a clock read costs 1 us
        return now[0]

    def sleep(seconds: float) -> None:  # a kernel that wakes us 70 us late, every time
        now[0] += seconds + 70e-6

    records = [Record(i * 0.001, "r", "cobs8", b"") for i in range(300)]
    result = replay(records, lambda r: None, clock=clock, keep_lateness=True, sleep=sleep)
    assert abs(result.sleep_overshoot - 70e-6) <= 4e-6  # it learned how late its sleeps wake
    assert max(result.lateness[50:]) < 5e-6  # once learned, every frame leaves on its deadline
    assert reads[0] < 300 * 20  # and waits by sleeping: spinning 0.2 ms a frame would read the clock ~60,000 times


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="timer slack is a Linux setting")
def test_replay_asks_for_a_fine_timer_slack_and_gives_it_back() -> None:
    import ctypes

    prctl = ctypes.CDLL(None).prctl
    get_slack = 30  # PR_GET_TIMERSLACK
    before = prctl(get_slack, 0, 0, 0, 0)
    during: list[int] = []
    replay([Record(0.0, "r", "cobs8", b""), Record(0.001, "r", "cobs8", b"")],
           lambda r: during.append(prctl(get_slack, 0, 0, 0, 0)), realtime=False)  # SCHED_FIFO has no slack at all
    assert during == [1000, 1000] and before != 1000
    assert prctl(get_slack, 0, 0, 0, 0) == before
