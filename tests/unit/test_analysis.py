"""The analysis core: convergence per write, active senders, conflicts, bandwidth; bulk and per-record reading agree."""

from __future__ import annotations

from pathlib import Path

import pytest

from vstig_hw.analysis import NO_SENDER, Analyzer, Report
from vstig_hw.capture.analyzefile import analyze_captures
from vstig_hw.capture.fastlog import parse_chunk
from vstig_hw.capture.filters import Filter
from vstig_hw.wire import Message, Op, encode

T0 = 1_700_000_000.0


def _report(rows: list[tuple[float, str, int, Message]], **options: object) -> Report:
    analyzer = Analyzer(**options)  # type: ignore[arg-type]
    analyzer.add_messages((T0 + t, analyzer.link(link), sender, msg) for t, link, sender, msg in rows)
    return analyzer.report()


def put(key: int, value: int, ts: int, robot: int) -> Message:
    return Message(Op.PUT, key, value, ts, robot)


def get(key: int, value: int, ts: int, robot: int) -> Message:
    return Message(Op.GET, key, value, ts, robot)


def test_a_write_converges_when_the_last_active_sender_shows_it_or_newer() -> None:
    report = _report([
        (1.0, "can0", 1, put(3, 77, 1, 1)),  # robot 1 writes
        (1.1, "can0", 2, get(3, 0, 0, 2)),  # robot 2 does not know it yet
        (1.3, "can0", 2, put(3, 77, 1, 1)),  # ... now relays it
        (1.4, "can0", 3, get(3, 78, 2, 3)),  # robot 3 shows a newer write: caught up too
        (1.6, "can0", 4, get(3, 77, 1, 1)),  # robot 4 asks with it
    ])
    first, newer = report.writes
    assert (first.key, first.value, first.timestamp, first.robot, first.link) == (3, 77, 1, 1, "can0")
    assert first.t == pytest.approx(T0 + 1.0)
    assert first.senders_total == 4 and first.behind == ()
    assert first.caught_up_after == pytest.approx((0.0, 0.3, 0.4, 0.6))
    assert first.converged_after == pytest.approx(0.6)
    assert newer.converged_after is None and newer.behind == (1, 2, 4)
    assert newer.senders_caught_up == 1
    summary = report.convergence()
    assert summary["converged"] == 1 and summary["median"] == pytest.approx(0.6)


def test_only_senders_heard_within_the_window_count() -> None:
    rows = [(0.0, "can0", 9, get(3, 0, 0, 9)),  # robot 9 leaves long before the write
            (100.0, "can0", 1, put(3, 5, 1, 1)),
            (100.5, "can0", 2, put(3, 5, 1, 1))]
    assert _report(rows, window=10.0).writes[0].converged_after == pytest.approx(0.5)
    wide = _report(rows, window=200.0).writes[0]
    assert wide.converged_after is None and wide.behind == (9,)


@pytest.mark.parametrize(("rule", "winner"), [("robot", 2), ("value", 1)])
def test_a_conflict_is_settled_by_the_chosen_rule(rule: str, winner: int) -> None:
    report = _report([(0.0, "can0", 1, put(3, 900, 1, 1)), (0.0, "can0", 2, put(3, 100, 1, 2)),
                      (0.5, "can0", 1, get(3, 100, 1, 2)), (0.5, "can0", 2, get(3, 900, 1, 1))],
                     conflict=rule)
    by_robot = {w.robot: w for w in report.writes}
    assert by_robot[winner].rank == 1 and by_robot[3 - winner].rank == 0
    assert by_robot[3 - winner].converged_after == 0.0  # both senders showed the winner from the start
    assert by_robot[winner].converged_after == pytest.approx(0.5)
    assert report.conflicts == 2


def test_timestamps_compare_across_the_wrap() -> None:
    report = _report([(0.0, "can0", 1, put(3, 1, 65535, 1)), (1.0, "can0", 1, put(3, 2, 1, 1)),
                      (2.0, "can0", 2, get(3, 2, 1, 1))])
    old, wrapped = report.writes
    assert (old.timestamp, wrapped.timestamp) == (65535, 1) and wrapped.rank > old.rank
    assert wrapped.converged_after == pytest.approx(1.0)


def test_bandwidth_first_copies_and_rebroadcasts() -> None:
    report = _report([(0.0, "can0", 1, put(3, 7, 1, 1)), (0.5, "can0", 2, put(3, 7, 1, 1)),
                      (1.0, "can0", 3, put(3, 7, 1, 1)), (2.0, "can0", 3, get(3, 7, 1, 1))])
    assert (report.first_copies, report.rebroadcasts, report.conflicts) == (1, 2, 0)
    assert report.duration == pytest.approx(2.0)
    link = report.links["can0"]
    assert (link.messages, link.puts, link.gets, link.bytes) == (4, 3, 1, 32)
    assert {s: t.messages for s, t in report.senders.items()} == {1: 1, 2: 1, 3: 2}


def test_a_link_that_names_no_sender_reports_when_each_write_was_heard() -> None:
    report = _report([(0.0, "radio", NO_SENDER, put(3, 7, 1, 1)), (0.2, "can0", 5, put(3, 7, 1, 1)),
                      (0.7, "radio", NO_SENDER, get(3, 7, 1, 1))])
    (write,) = report.writes
    assert report.links_without_sender == ["radio"]
    assert write.link == "radio" and write.senders_total == 1 and write.converged_after == pytest.approx(0.2)
    radio = write.heard["radio"]
    assert (radio.first - T0, radio.last - T0, radio.copies) == (pytest.approx(0.0), pytest.approx(0.7), 2)
    assert write.heard["can0"].copies == 1


def test_a_capture_of_serial_links_only_measures_no_convergence() -> None:
    report = _report([(0.0, "radio", NO_SENDER, put(3, 7, 1, 1))])
    assert report.writes[0].senders_total == 0 and report.writes[0].converged_after is None
    assert report.convergence()["measured"] == 0


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="window"):
        Analyzer(window=0)
    with pytest.raises(ValueError, match="conflict rule"):
        Analyzer(conflict="oldest")  # type: ignore[arg-type]


def _candump(path: Path, frames: list[tuple[float, int, Message]]) -> None:
    path.write_text("".join(f"({T0 + t:.6f}) can0 {0x600 | msg.op << 8 | sender:03X}#{encode(msg).hex().upper()}\n"
                            for t, sender, msg in frames))


def test_bulk_and_per_record_reading_give_the_same_report(tmp_path: Path) -> None:
    frames = []
    for step in range(300):
        for robot in range(6):
            known = min(step // 3 + 1, 40)  # each robot lags the newest write by a few steps
            ts = max(1, known - robot)
            frames.append((step * 0.1, robot, get(step % 2, ts % 7, ts, (ts * 5) % 6)))
    log = tmp_path / "swarm.log"
    _candump(log, frames)
    assert parse_chunk(log.read_bytes(), lambda can_id: can_id >> 8 & 1, {}) is not None  # uniform: bulk path
    empty = tmp_path / "empty.log"
    empty.write_text("")
    bulk, by_record = Analyzer(), Analyzer()
    analyze_captures([str(log)], bulk)  # one candump log: the columnar path
    analyze_captures([str(log), str(empty)], by_record)  # two files: merged record by record
    a, b = bulk.report(), by_record.report()
    assert a.messages == b.messages == len(frames)
    assert [(w.key, w.timestamp, w.robot, w.senders_total, w.behind) for w in a.writes] == \
           [(w.key, w.timestamp, w.robot, w.senders_total, w.behind) for w in b.writes]
    assert [w.caught_up_after for w in a.writes] == [pytest.approx(w.caught_up_after, abs=1e-6) for w in b.writes]
    assert a.convergence()["converged"] > 0


def test_key_filter_keeps_one_key(tmp_path: Path) -> None:
    log = tmp_path / "two_keys.log"
    _candump(log, [(0.0, 1, put(3, 7, 1, 1)), (0.1, 1, put(4, 8, 1, 1)), (0.2, 2, get(4, 8, 1, 1))])
    analyzer = Analyzer()
    analyze_captures([str(log)], analyzer, keep=Filter(keys=frozenset({4})))
    report = analyzer.report()
    assert [w.key for w in report.writes] == [4] and report.messages == 2


def test_timeline_counts_each_links_messages_per_control_step() -> None:
    analyzer = Analyzer()
    can0, radio = analyzer.link("can0"), analyzer.link("radio0")
    later = [(T0 + 1.0, can0, 1, put(3, 7, 1, 1)), (T0 + 1.3, can0, 2, get(3, 7, 1, 1)),
             (T0 + 1.3, radio, NO_SENDER, put(3, 7, 1, 1)), (T0 + 1.35, can0, 2, put(3, 7, 1, 1))]
    analyzer.add_messages(later)
    analyzer.report()  # aggregates what came so far: the next batch starts earlier than every slot
    analyzer.add_messages([(T0 + 0.8, radio, NO_SENDER, get(3, 7, 1, 1))])
    analyzer.add_messages([(T0 + 1e9, can0, 3, get(3, 7, 1, 1))])  # a clock decades off: one more slot, not 10^10
    analyzer.report()
    analyzer.add_messages([(T0 + 1.31, can0, 2, get(3, 7, 1, 1))])
    report = analyzer.report()
    assert set(report.timelines) == {"can0", "radio0"}
    can_line, radio_line = report.timelines["can0"], report.timelines["radio0"]
    assert can_line.start == radio_line.start == pytest.approx(T0 + 1.0)  # slots count from the first message read
    far = round((1e9 - 1.0) / 0.1)
    assert (can_line.slots.tolist(), can_line.counts.tolist()) == ([0, 3, far], [1, 3, 1])  # 1.3, 1.31, 1.35: one slot
    assert (radio_line.slots.tolist(), radio_line.counts.tolist()) == ([-2, 3], [1, 1])
    assert sum(int(t.counts.sum()) for t in report.timelines.values()) == report.messages == 7


def test_messages_beyond_one_batch_all_count() -> None:
    rows = [(i * 0.001, "can0", i % 8, get(3, 7, 1 + i // 1000, 1)) for i in range(150_000)]  # over two batches
    report = _report(rows)
    assert report.messages == 150_000
    assert len(report.writes) == 150 and report.links["can0"].gets == 150_000
