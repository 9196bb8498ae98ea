"""The index `vstig why` reads captures into: a candump log read in bulk (fastlog) files every message as the
record-by-record path does, and decision notes read back as written."""

from __future__ import annotations

import sys
from pathlib import Path

from vstig_hw.capture.decision_notes import counted_note, decisions_in, refusal_note
from vstig_hw.capture.trace import read_trace
from vstig_hw.capture.why import explain

sys.path.insert(0, str(Path(__file__).parents[2]))
from benchmarks.bench_analyze import _write_swarm_log


def test_the_bulk_candump_path_files_what_the_record_path_files(tmp_path: Path) -> None:
    log = tmp_path / "swarm.log"
    _write_swarm_log(str(log), 20_000)
    bulk = read_trace([str(log)])
    lined = read_trace([str(log)], shifts=[0.0])  # shifts take the record-by-record path
    assert bulk.messages == lined.messages > 19_000
    assert sorted(bulk.senders) == sorted(lined.senders) and len(bulk.senders) == 64
    assert bulk.keys == lined.keys and len(bulk.keys) == 25
    for key in bulk.keys[::4]:
        assert bulk.of(key) == lined.of(key) and bulk.of(key)
        assert explain(bulk, key, at=1.0) == explain(lined, key, at=1.0)
    assert bulk.last_heard(1.0) == lined.last_heard(1.0)


def test_decision_notes_read_back_as_written() -> None:
    lines = ["# " + counted_note(12.5, "ttyUSB1", "tx_overflow", 3) + "\n",
             "# " + refusal_note(12.6, "can0", "drop_jump", 7, 3, 40001, 7) + "\n",
             "# " + refusal_note(12.7, "radio", "drop_key", None, 500, 2, 9) + "\n",
             "# vstig clock 3f2a9c1e5b7d4a60\n", "# vstig decision (garbage\n"]
    first, second, third = decisions_in(lines)
    assert (first.t, first.link, first.reason, first.count, first.entry) == (12.5, "ttyUSB1", "tx_overflow", 3, None)
    assert (second.sender, second.entry) == (7, (3, 40001, 7))
    assert third.sender is None and third.entry == (500, 2, 9)


def test_an_mcap_capture_keeps_what_the_gateway_sent_apart_and_its_notes(tmp_path: Path) -> None:
    from vstig_hw import Message, Op
    from vstig_hw.capture.clock_notes import clock_note, read_clock_notes
    from vstig_hw.capture.files import RotatingCapture
    from vstig_hw.capture.records import Record, read_capture
    from vstig_hw.clocks import CLOCK_ID
    from vstig_hw.framing import make_serial_framing

    cobs8 = make_serial_framing("cobs8")
    path = tmp_path / "bridge.mcap"
    capture = RotatingCapture(str(path), "mcap")
    capture.write(Record(100.0, "radio", "cobs8", cobs8.encode(Message(Op.PUT, 3, 9, 4, 7))[0]))
    capture.write(Record(100.5, "radio", "cobs8", cobs8.encode(Message(Op.PUT, 3, 9, 4, 7))[0], "tx"))
    capture.note(clock_note())
    capture.note(refusal_note(100.6, "radio", "drop_jump", None, 3, 999, 7))
    capture.close()
    assert capture.takes_notes
    assert read_clock_notes(str(path)).clock == CLOCK_ID
    assert [r.direction for r in read_capture(str(path))] == ["rx", "tx"]
    trace = read_trace([str(path)])
    assert [(s.sent, s.link, s.t) for s in trace.of(3)] == [(False, "radio", 0.0), (True, "radio", 0.5)]
    (refused,) = trace.decisions
    assert refused.entry == (3, 999, 7) and abs(refused.t - 0.6) < 1e-6
