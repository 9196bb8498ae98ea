"""`vstig analyze` on captures whose clock notes it must not believe outright: written here, read by the real CLI."""

from __future__ import annotations

import json
from pathlib import Path

from peers import run_vstig

from vstig_hw.wire import Message, Op, encode

A, B = "aaaaaaaaaaaaaaaa", "bbbbbbbbbbbbbbbb"


def _capture(path: Path, clock: str, notes: list[str]) -> str:
    lines = ["# vstig zenoh capture v1", f"# vstig clock {clock}"]
    for n in range(1, 6):
        payload = encode(Message(Op.PUT, 3, n, n, 7)).hex()
        lines.append(f"(1700000000.{n:06d}) zenoh-lab zenoh rx vstig/lab/0/7 {payload}")
    path.write_text("\n".join([*lines, *(f"# vstig clock-offset (1700000001.000000) {note}" for note in notes)]) + "\n")
    return str(path)


def _shift(*argv: str) -> tuple[object, str]:
    done = run_vstig("analyze", *argv, "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)["capture"]["clocks"][1], done.stderr


def test_offsets_noted_before_answers_were_checked_are_used_only_when_trusted(tmp_path: Path) -> None:
    a = _capture(tmp_path / "a.cap", A, [f"{B} +0.250000000 0.000400000"])  # no marker: an older vstig's
    b = _capture(tmp_path / "b.cap", B, [])
    shift, said = _shift(a, b)
    assert shift is None
    assert "b.cap: no proved clock offset joins it to " in said and "(1 unproved not used" in said
    trusted, said = _shift(a, b, "--trust-clock-notes")
    assert trusted == {"shift_s": 0.25, "error_s": 0.0004} and "b.cap: on " in said


def test_a_clock_two_certificates_answered_for_is_not_merged_through(tmp_path: Path) -> None:
    a = _capture(tmp_path / "a.cap", A, [f"{B} +0.001000000 0.000400000 cert=gw-b",
                                         f"{B} +1000.000000000 0.000100000 cert=gw-insider"])
    b = _capture(tmp_path / "b.cap", B, [f"{A} -0.001000000 0.000500000 unproved"])
    shift, said = _shift(a, b)
    assert shift is None
    assert f"clock {B}: answered for by more than one certificate (gw-b, gw-insider)" in said
    proved, _ = _shift(_capture(tmp_path / "c.cap", A, [f"{B} +0.001000000 0.000400000 cert=gw-b"]), b)
    assert proved == {"shift_s": 0.001, "error_s": 0.0004}
