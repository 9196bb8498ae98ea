"""`vstig record`, `decode` and `replay` of a CAN link, as subprocesses on python-can's slcan driver.

Why slcan on a pty: python-can's virtual bus lives inside one process, and
udp_multicast needs a private network namespace and drops frames in bursts. A
pty whose master side plays the adapter crosses the process boundary through
a real python-can driver, needs no privileges, and loses nothing.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import can
import pytest
from peers import SlcanAdapter, run_vstig, start_vstig, stop, wait_for

from vstig_hw import Message, Op, encode

pytestmark = pytest.mark.slow  # python-can's slcan driver sleeps 2 s after opening its port

MESSAGES = [Message(Op.PUT, 3, 1000 + i, i + 1, 7) for i in range(5)] + [Message(Op.GET, 4, 0, 0, 9)]


def _frame(msg: Message) -> can.Message:
    sender = msg.robot & 0xFF
    return can.Message(arbitration_id=0x600 | int(msg.op) << 8 | sender, data=encode(msg), is_extended_id=False)


def _record_messages(adapter: SlcanAdapter, capture: Path) -> subprocess.Popen[str]:
    """`vstig record` on the adapter's bus, once it has opened it and been sent MESSAGES."""
    recorder = start_vstig("record", f"can:slcan:{adapter.path}", "-o", str(capture))
    try:
        wait_for(lambda: "O" in adapter.commands or "L" in adapter.commands, 30)
    except AssertionError:
        recorder.kill()
        recorder.communicate()
        adapter.close()
        raise
    for msg in MESSAGES:
        adapter.inject(_frame(msg))
    return recorder


def test_record_decode_replay_round_trip(tmp_path: Path) -> None:
    capture = tmp_path / "swarm.log"
    adapter = SlcanAdapter()
    recorder = _record_messages(adapter, capture)
    try:
        adapter.inject(can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False))  # not ours
        wait_for(lambda: capture.exists() and capture.read_text().count("\n") >= len(MESSAGES), 20)
    finally:
        _out, err = stop(recorder)
        adapter.close()
    assert recorder.returncode == 0, err
    assert f"{len(MESSAGES)} units" in err  # the kernel-side filter kept the foreign frame out, or it is counted

    decoded = run_vstig("decode", str(capture), "--format", "jsonl")
    assert decoded.returncode == 0, decoded.stderr
    rows = [json.loads(line) for line in decoded.stdout.splitlines()]
    assert [(r["op"], r["key"], r["value"], r["timestamp"], r["robot"]) for r in rows] == [
        (m.op.name, m.key, m.value, m.timestamp, m.robot) for m in MESSAGES]
    assert all(r["link"] == rows[0]["link"] and r["can_id"] >= 0x600 for r in rows)

    table = run_vstig("replay", str(capture), "--table")
    assert table.returncode == 0 and "1004" in table.stdout.split("\n", 2)[2]  # key 3 ends at value 1004

    target = SlcanAdapter()
    try:
        replayed = run_vstig("replay", str(capture), "--onto", f"can:slcan:{target.path}", "--speed", "10")
        assert replayed.returncode == 0, replayed.stderr
        wait_for(lambda: len(target.sent) >= len(MESSAGES), 10)
    finally:
        target.close()
    assert [bytes(f.data) for f in target.sent] == [encode(m) for m in MESSAGES]
    assert [f.arbitration_id for f in target.sent] == [_frame(m).arbitration_id for m in MESSAGES]


def test_a_blf_recording_killed_outright_keeps_what_it_recorded(tmp_path: Path) -> None:
    capture = tmp_path / "swarm.blf"
    adapter = SlcanAdapter()
    recorder = _record_messages(adapter, capture)
    try:
        wait_for(lambda: capture.exists() and capture.stat().st_size > 200, 20)  # a block reached the disk
    finally:
        recorder.kill()  # SIGKILL: no chance to close the file
        recorder.communicate(timeout=10)
        adapter.close()
    decoded = run_vstig("decode", str(capture), "--format", "jsonl")
    assert decoded.returncode == 0, decoded.stderr
    assert len(decoded.stdout.splitlines()) == len(MESSAGES)


def test_blf_rotation_keeps_each_file_near_the_limit(tmp_path: Path) -> None:
    from vstig_hw.capture.files import RotatingCapture
    from vstig_hw.capture.records import Record

    capture = RotatingCapture(str(tmp_path / "r.blf"), "can", max_bytes=10_000)
    for i in range(3000):
        frame = can.Message(timestamp=1700000000 + i / 1000, arbitration_id=0x600 | i % 200,
                            data=i.to_bytes(8, "big"), is_extended_id=False)
        capture.write(Record(frame.timestamp, "can0", "can", frame))
    capture.close()
    sizes = [Path(name).stat().st_size for name in capture.files]
    assert len(sizes) > 1 and max(sizes) <= 10_000 + 4096, sizes  # at most one size check's worth over
