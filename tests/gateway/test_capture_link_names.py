"""ASC and BLF captures keep each record's link name and exact time, however many links and frames."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from vstig_hw.capture.files import RotatingCapture
from vstig_hw.capture.records import CaptureError, Record, read_capture

T0 = 1700000000.123456


def _write(path: Path, links: list[str]) -> list[tuple[float, str, int]]:
    writer = RotatingCapture(str(path), "can")
    written = []
    for i, link in enumerate(links):
        t = T0 + i * 1e-3 + 1e-6 * (i % 7)
        frame = can.Message(timestamp=t, arbitration_id=0x600 | i % 0x100, data=i.to_bytes(4, "big") * 2,
                            is_extended_id=False)
        writer.write(Record(t, link, "can", frame))
        written.append((round(t, 6), link, frame.arbitration_id))
    writer.close()
    return written


@pytest.mark.parametrize("ext", [".asc", ".asc.gz", ".blf"])
def test_several_links_come_back_by_name_with_their_exact_times(tmp_path: Path, ext: str) -> None:
    written = _write(tmp_path / f"bus{ext}", ["can0", "lab", "can1", "lab", "0", "can0"])
    back = [(round(r.t, 6), r.link, r.unit.arbitration_id) for r in read_capture(str(tmp_path / f"bus{ext}"))]
    assert back == written


def test_a_link_first_heard_deep_in_a_big_blf_is_named_from_its_block(tmp_path: Path) -> None:
    """Tens of thousands of frames fill several compressed blocks; the late link's note sits among them."""
    links = ["can0"] * 40000 + ["late"] + ["can0", "late"] * 5000
    written = _write(tmp_path / "big.blf", links)
    back = [(round(r.t, 6), r.link, r.unit.arbitration_id) for r in read_capture(str(tmp_path / "big.blf"))]
    assert back == written


def test_a_second_link_into_a_csv_names_the_file(tmp_path: Path) -> None:
    with pytest.raises(CaptureError, match=r"bus\.csv: a \.csv capture names no link: 'b' cannot join 'a'"):
        _write(tmp_path / "bus.csv", ["a", "a", "b"])
