"""decode's progress: every format reports how far it got; the bar goes to a terminal stderr only."""

from __future__ import annotations

import io
import os
import subprocess
from pathlib import Path

import can
import pytest
from peers import VSTIG, run_vstig_on_a_terminal_stderr

from vstig_hw.capture.decoded import decode_file
from vstig_hw.capture.files import RotatingCapture
from vstig_hw.capture.records import Damage, Record

FRAMES = 10_000


def _capture(path: Path, medium: str) -> None:
    capture = RotatingCapture(str(path), medium)
    for i in range(FRAMES):
        t = 1700000000 + i / 1000
        if medium == "can":
            data = bytes([0, i % 100, 0, 1, 0, i % 250 + 1, 0, 7])
            unit: object = can.Message(timestamp=t, arbitration_id=0x600 | i % 100, data=data, is_extended_id=False)
        else:
            unit = bytes([4, 1, 2, 3, 0])  # a cobs8 chunk; what it holds does not matter here
        capture.write(Record(t, "can0" if medium == "can" else "radio0", "can" if medium == "can" else "cobs8", unit))
    capture.close()


@pytest.mark.parametrize(("name", "fmt"), [("x.log", "jsonl"), ("x.log", "text"), ("x.asc", "csv"),
                                           ("x.csv", "jsonl"), ("x.blf", "text"), ("x.cap", "jsonl")])
def test_progress_advances_to_the_end_for_every_format(tmp_path: Path, name: str, fmt: str) -> None:
    path = tmp_path / name
    _capture(path, "serial" if name.endswith(".cap") else "can")
    seen: list[int] = []
    decode_file(str(path), io.StringIO(), fmt, progress=seen.append, damage=Damage(skip=True))
    assert seen and seen == sorted(seen) and seen[-1] == os.path.getsize(path)


def test_the_bar_goes_to_a_terminal_stderr_and_never_into_the_output(tmp_path: Path) -> None:
    log = tmp_path / "big.log"
    lines = (f"({1700000000 + i / 1000:.6f}) can0 6{i % 100:02X}#00{i % 100:02X}0001{i % 250 + 1:04X}0007\n"
             for i in range(40_000))
    log.write_text("".join(lines))
    assert log.stat().st_size > 1 << 20
    quiet = subprocess.run([VSTIG, "decode", str(log), "--format", "csv"], capture_output=True, timeout=120,
                           check=True)
    out = tmp_path / "out.csv"
    with open(out, "wb") as stdout:
        code, shown = run_vstig_on_a_terminal_stderr("decode", str(log), "--format", "csv", stdout=stdout)
    assert code == 0
    assert out.read_bytes() == quiet.stdout and quiet.stdout.count(b"\n") == 40_001
    assert b"decoding big.log" in shown and b"40000 messages" in shown
