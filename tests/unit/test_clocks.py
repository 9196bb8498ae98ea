"""Clock offsets from round trips (vstig_hw.clocks) and captures put on one clock (capture.clock_notes): data in,
data out."""

from __future__ import annotations

from pathlib import Path

import pytest

from vstig_hw.capture.clock_notes import CaptureClock, Shift, offset_note, read_clock_notes, shifts
from vstig_hw.clocks import ClockOffset, OffsetFilter, measure


def test_a_round_trip_bounds_the_offset_by_half_its_delay() -> None:
    trip = measure("b", sent=100.000, peer_time=100.260, received=100.020)
    assert trip.offset == pytest.approx(0.250) and trip.error == pytest.approx(0.010) and trip.at == 100.020
    with pytest.raises(ValueError):
        measure("b", sent=2.0, peer_time=1.0, received=1.0)


def test_the_filter_keeps_the_tightest_of_the_recent_round_trips() -> None:
    kept = OffsetFilter(window=3)
    kept.add(measure("b", 0.0, 0.30, 0.10))  # error 0.05: a queued reply
    best = kept.add(measure("b", 1.0, 1.2505, 1.001))  # error 0.0005
    assert best.error == pytest.approx(0.0005)
    kept.add(measure("b", 2.0, 2.27, 2.04))
    kept.add(measure("b", 3.0, 3.27, 3.04))
    assert kept.add(measure("b", 4.0, 4.27, 4.04)).error == pytest.approx(0.02)  # the tight one left the window


def test_captures_are_shifted_onto_the_first_ones_clock_by_the_tightest_trip_either_side_measured() -> None:
    a = CaptureClock("aa", [ClockOffset("bb", 0.2490, 0.004, 1.0), ClockOffset("cc", -1.0, 0.001, 1.0)])
    b = CaptureClock("bb", [ClockOffset("aa", -0.2502, 0.0003, 2.0)])  # its side was tighter
    lone = CaptureClock("dd", [])
    unnamed = CaptureClock(None, [])
    assert shifts([a, b, lone, unnamed]) == [Shift(0.0, 0.0), Shift(0.2502, 0.0003), None, None]
    assert shifts([b, a]) == [Shift(0.0, 0.0), Shift(-0.2502, 0.0003)]


def test_clock_notes_read_back(tmp_path: Path) -> None:
    capture = tmp_path / "a.cap"
    trip = ClockOffset("9b1c0d2e3f4a5b6c", -0.25, 0.0004, 1700000000.25)
    capture.write_text("# vstig zenoh capture v1\n# vstig clock 3f2a9c1e5b7d4a60\n"
                       f"(1700000000.000000) zenoh-lab zenoh rx vstig/lab/0/1 00\n# {offset_note(trip)}\n")
    read = read_clock_notes(str(capture))
    assert read.clock == "3f2a9c1e5b7d4a60" and read.offsets == [trip]


def test_two_recorders_that_measured_the_same_hub_are_joined_through_it() -> None:
    a = CaptureClock("aa", [ClockOffset("hub", 0.010, 0.0004, 1.0)])  # the hub is 10 ms ahead of a
    b = CaptureClock("bb", [ClockOffset("hub", -0.240, 0.0005, 1.0)])  # and 240 ms behind b
    (first, second) = shifts([a, b])
    assert first == Shift(0.0, 0.0)
    assert second is not None and second.seconds == pytest.approx(0.250) and second.error == pytest.approx(0.0009)
