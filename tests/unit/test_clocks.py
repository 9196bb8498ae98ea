"""Clock offsets from round trips (vstig_hw.clocks) and captures put on one clock (capture.clock_notes): data in,
data out."""

from __future__ import annotations

from pathlib import Path

import pytest

from vstig_hw.capture.clock_notes import CaptureClock, Shift, disputed, offset_note, read_clock_notes, shifts
from vstig_hw.clocks import MAX_PEERS, STALE_S, ClockOffset, OffsetFilter, measure
from vstig_hw.transports.zenoh_clock import _proof_name, peer_time


def test_a_round_trip_bounds_the_offset_by_half_its_delay() -> None:
    trip = measure("b", sent=100.000, peer_time=100.260, received=100.020)
    assert trip.offset == pytest.approx(0.250) and trip.error == pytest.approx(0.010) and trip.at == 100.020
    with pytest.raises(ValueError):
        measure("b", sent=2.0, peer_time=1.0, received=1.0)


def test_the_filter_keeps_the_tightest_of_the_recent_round_trips() -> None:
    kept = OffsetFilter(window=3)
    kept.add(measure("b", 0.0, 0.30, 0.10))  # error 0.05: a queued reply
    best = kept.add(measure("b", 1.0, 1.2505, 1.001))  # error 0.0005
    assert best is not None and best.error == pytest.approx(0.0005)
    kept.add(measure("b", 2.0, 2.27, 2.04))
    kept.add(measure("b", 3.0, 3.27, 3.04))
    later = kept.add(measure("b", 4.0, 4.27, 4.04))
    assert later is not None and later.error == pytest.approx(0.02)  # the tight one left the window


def test_captures_are_shifted_onto_the_first_ones_clock_by_the_tightest_trip_either_side_measured() -> None:
    a = CaptureClock("aa", [ClockOffset("bb", 0.2490, 0.004, 1.0, "gw-b"), ClockOffset("cc", -1.0, 0.001, 1.0, "c")])
    b = CaptureClock("bb", [ClockOffset("aa", -0.2502, 0.0003, 2.0, "gw-a")])  # its side was tighter
    lone = CaptureClock("dd", [])
    unnamed = CaptureClock(None, [])
    assert shifts([a, b, lone, unnamed]) == [Shift(0.0, 0.0), Shift(0.2502, 0.0003), None, None]
    assert shifts([b, a]) == [Shift(0.0, 0.0), Shift(-0.2502, 0.0003)]


def test_clock_notes_read_back(tmp_path: Path) -> None:
    capture = tmp_path / "a.cap"
    proved = ClockOffset("9b1c0d2e3f4a5b6c", -0.25, 0.0004, 1700000000.25, "gw-b%20east")
    unproved = ClockOffset("0d2e3f4a5b6c9b1c", 1000.0, 0.0004, 1700000000.5)
    legacy = "# vstig clock-offset (1700000001.000000) 9b1c0d2e3f4a5b6c -0.250000000 0.000400000"  # before proofs
    capture.write_text("# vstig zenoh capture v1\n# vstig clock 3f2a9c1e5b7d4a60\n"
                       f"(1700000000.000000) zenoh-lab zenoh rx vstig/lab/0/1 00\n# {offset_note(proved)}\n"
                       f"# {offset_note(unproved)}\n{legacy}\n# vstig clock-offset (1.0) aa +{'9' * 400}.0 0.1\n")
    read = read_clock_notes(str(capture))
    assert read.clock == "3f2a9c1e5b7d4a60"
    assert read.offsets == [proved, unproved, ClockOffset("9b1c0d2e3f4a5b6c", -0.25, 0.0004, 1700000001.0)]
    assert offset_note(unproved).endswith(" unproved")


def test_two_recorders_that_measured_the_same_hub_are_joined_through_it() -> None:
    a = CaptureClock("aa", [ClockOffset("hub", 0.010, 0.0004, 1.0, "gw-hub")])  # the hub is 10 ms ahead of a
    b = CaptureClock("bb", [ClockOffset("hub", -0.240, 0.0005, 1.0, "gw-hub")])  # and 240 ms behind b
    (first, second) = shifts([a, b])
    assert first == Shift(0.0, 0.0)
    assert second is not None and second.seconds == pytest.approx(0.250) and second.error == pytest.approx(0.0009)


def test_only_proved_offsets_join_captures_unless_every_note_is_trusted() -> None:
    a = CaptureClock("aa", [ClockOffset("bb", 1000.0, 0.0001, 1.0)])  # a forger's answer under b's clock id
    b = CaptureClock("bb", [ClockOffset("aa", -0.002, 0.0005, 1.0, "gw-a")])
    assert shifts([a, b]) == [Shift(0.0, 0.0), Shift(0.002, 0.0005)]  # b's proved side, not the tighter forgery
    assert shifts([a, b], trust_unproved=True) == [Shift(0.0, 0.0), Shift(1000.0, 0.0001)]
    assert shifts([a, CaptureClock("bb", [])]) == [Shift(0.0, 0.0), None]


def test_a_clock_two_certificates_answered_for_joins_nothing() -> None:
    a = CaptureClock("aa", [ClockOffset("bb", 0.001, 0.0005, 1.0, "gw-b"), ClockOffset("bb", 1000.0, 0.0001, 2.0,
                                                                                        "gw-insider")])
    b = CaptureClock("bb", [])
    assert disputed([a, b]) == {"bb": ["gw-b", "gw-insider"]}
    assert shifts([a, b]) == [Shift(0.0, 0.0), None]


def test_the_filter_tracks_a_bounded_number_of_clocks_and_keeps_proved_ones() -> None:
    kept = OffsetFilter()
    for n in range(MAX_PEERS):
        assert kept.add(measure(f"{n:016x}", 0.0, 0.0, 0.001)) is not None
    assert kept.add(measure("f" * 16, 1.0, 1.0, 1.001)) is None  # a flood's next made-up id: refused
    proved = kept.add(measure("e" * 16, 1.0, 1.0, 1.001, "gw-e"))  # a proved clock takes an unproved one's place
    assert proved is not None and proved.proof == "gw-e" and len(kept.estimates()) == MAX_PEERS
    for n in range(MAX_PEERS):  # a full filter of proved clocks lets no unproved one in
        kept.add(measure(f"{n:016x}", 2.0, 2.0, 2.001, "gw"))
    assert kept.add(measure("d" * 16, 3.0, 3.0, 3.001)) is None
    late = STALE_S + 10
    assert kept.add(measure("d" * 16, late, late, late + 0.001)) is not None  # the quiet ones gave their place up
    assert len(kept.estimates()) == MAX_PEERS


def test_a_peers_unproved_answers_never_stand_in_for_its_proved_ones() -> None:
    kept = OffsetFilter()
    kept.add(measure("b" * 16, 0.0, 0.0, 0.010, "gw-b"))
    kept.add(measure("b" * 16, 0.0, 1000.0, 0.0001))  # tighter, forged
    estimates = {trip.proof: trip for trip in kept.estimates()}
    assert estimates["gw-b"].offset == pytest.approx(-0.005) and estimates[None].offset == pytest.approx(1000, 0.01)


@pytest.mark.parametrize("answer", [b"9" * 400, b"9" * 20, b"", b"-1", b"1e9", b" 1", "\u0661".encode(), b"12\n"])
def test_what_is_no_clocks_answer_is_refused_not_raised(answer: bytes) -> None:
    assert peer_time(answer) is None


def test_a_clocks_answer_is_its_nanoseconds_in_seconds() -> None:
    assert peer_time(b"1700000000250000000") == pytest.approx(1700000000.25)


def test_a_certificate_name_is_kept_without_spaces_or_line_breaks() -> None:
    name = _proof_name("gw b\n# vstig clock-offset (1.0) aa +5.0 0.1 cert=x" + "x" * 500)
    assert name is not None and len(name) == 128 and not any(ch.isspace() for ch in name)
    assert _proof_name("gw-b") == "gw-b" and _proof_name(None) is None and _proof_name("") is None
