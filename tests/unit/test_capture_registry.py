"""The capture registry (capture.records): every entry resolves, and `sniff` tells a format as readers expect.

A registry line naming a module or function that does not exist would fail only when
a file of that format is read: each is resolved here.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import pytest

from vstig_hw.capture import serial_log, zenoh_log
from vstig_hw.capture.records import (
    LINE_CAPTURE_HEADERS,
    READABLE_EXTENSIONS,
    READERS,
    WRITERS,
    CaptureError,
    read_capture,
    reader_for,
    sniff,
    writer_class,
)


def test_every_reader_and_writer_in_the_registry_exists() -> None:
    for fmt in READERS:
        reader = reader_for(fmt)
        assert list(inspect.signature(reader).parameters) == ["path", "damage", "opened"], fmt
    for medium in WRITERS:
        assert inspect.isclass(writer_class(medium)), medium


def test_every_readable_extension_and_line_capture_has_a_reader() -> None:
    assert set(READERS) == {*READABLE_EXTENSIONS, *LINE_CAPTURE_HEADERS.values()}


def test_the_line_capture_headers_are_the_ones_their_writers_write() -> None:
    assert {serial_log.HEADER.rsplit(" ", 1)[0]: "serial", zenoh_log.HEADER.rsplit(" ", 1)[0]: "zenoh"} \
        == LINE_CAPTURE_HEADERS


def test_a_line_capture_is_found_by_its_header_whatever_its_name(tmp_path: Path) -> None:
    path = tmp_path / "radio.log"  # a candump name, a serial capture inside
    path.write_text(f"{serial_log.HEADER}\n(1700000000.250000) radio0 cobs8 rx 0b01\n")
    assert sniff(str(path)) == "serial"
    assert [r.link for r in read_capture(str(path))] == ["radio0"]


def test_any_other_capture_is_found_by_its_extension(tmp_path: Path) -> None:
    path = tmp_path / "bus.ASC"  # any case
    path.write_bytes(b"")
    assert sniff(str(path)) == ".asc"


def test_an_unknown_extension_or_a_missing_file_is_one_line_naming_it(tmp_path: Path) -> None:
    odd = tmp_path / "notes.txt"
    odd.write_text("(1700000000.250000) can0 601#0003006400010001\n")
    with pytest.raises(CaptureError, match=r"notes\.txt: unknown capture type '\.txt'"):
        sniff(str(odd))
    with pytest.raises(CaptureError, match=r"gone\.log: no such file"):
        list(read_capture(str(tmp_path / "gone.log")))
