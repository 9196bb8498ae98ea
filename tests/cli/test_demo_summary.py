"""`vstig demo`'s summary explains itself: a legend for its columns, losses that add up, and every counter it
prints documented in docs/reference/counters.md. The demo runs as a process, on its real pty radios and CAN bus."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from peers import run_vstig

COUNTERS_MD = Path(__file__).resolve().parents[2] / "docs" / "reference" / "counters.md"
_LOST = re.compile(r"^(\w+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(\d+) of (\d+)(?: \((\d+)%\))?$")


@pytest.fixture(scope="module")
def summary() -> list[str]:
    done = run_vstig("demo", "--robots", "12", "--drop", "0.5", "--max-steps", "200", timeout=90)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


def test_each_medium_counts_copies_and_loses_about_drop_of_them(summary: list[str]) -> None:
    rows = {m[1]: m.groups() for line in summary if (m := _LOST.match(line))}
    assert set(rows) == {"can", "cobs8", "epuck4"}, "\n".join(summary)
    for name, (_, robots, messages, frames, _bytes, lost, copies, percent) in rows.items():
        assert int(robots) == 4 and int(frames) >= int(messages) > 0, name
        # a frame has a copy per listener (3 other robots; on a radio the gateway too): lost counts copies
        assert int(copies) >= 3 * int(frames) > 0, name
        assert abs(100 * int(lost) / int(copies) - int(percent)) <= 0.5, name  # the percentage is of copies
        assert 0.35 < int(lost) / int(copies) < 0.65, (name, lost, copies)  # --drop 0.5


def test_the_summary_has_a_legend_for_its_columns(summary: list[str]) -> None:
    text = "\n".join(summary)
    assert "medium  robots messages frames  bytes  lost" in text and "framing drops: " in text
    for says in ("messages: the PUTs and GETs its robots sent", "lost: each frame reaches every other robot",
                 "--drop 0.5 loses each copy", "framing drops: frames a robot's framing threw away",
                 "the gateway's engine, for each message it heard:"):
        assert says in text.replace("\n  ", " "), text
    table = summary[1:summary.index(next(line for line in summary if line.startswith("the gateway's links")))]
    assert all(len(line) <= 80 for line in table), table  # the table and its legend read at 80 columns
    assert "conflict=" not in text and "same=" not in text  # the engine's outcomes are said in words
    assert re.search(r"^  \d+ conflicts? \(same timestamp, another robot: the larger value kept\)$", text, re.M), text


def test_every_counter_the_summary_prints_is_in_counters_md(summary: list[str]) -> None:
    documented = set(re.findall(r"`([a-z_<>]+)`", COUNTERS_MD.read_text()))
    printed = {name for line in summary if line.startswith("  ") and ": " in line and "=" in line
               for name in re.findall(r"(\w+)=\d+", line)}
    (drops,) = [line for line in summary if line.startswith("framing drops: ")]
    printed |= {f"drop_{name}" for name in re.findall(r"(\w+)=", drops)}
    assert {"in", "out", "rx", "tx"} <= printed, summary
    assert printed <= documented, printed - documented
    for column in ("messages", "frames", "copies", "lost"):  # the demo's own, under their section
        assert f"`{column}`" in COUNTERS_MD.read_text(), column


def test_the_live_table_of_a_long_run_fits_80_columns() -> None:
    import io

    from rich.console import Console

    from vstig_cli.commands.demo import _live_table
    from vstig_hw.counters import Counters
    from vstig_hw.demo.swarm import Medium

    media = [Medium(name, counters=Counters(messages=10_000, frames=30_000, bytes=240_000, copies=345_000,
                                            lost=259_400, drop_duplicate=2_200)) for name in ("can", "cobs8", "epuck4")]
    console = Console(width=80, file=io.StringIO(), record=True)
    console.print(_live_table(120, media, 29, 240))
    lines = console.export_text().splitlines()
    assert all(len(line) <= 80 for line in lines) and "…" not in "".join(lines), "\n".join(lines)
    rows = [line for line in lines if line.lstrip().startswith(("can ", "cobs8 ", "epuck4 "))]
    assert len(rows) == 3 and all("259400 of 345000 (75%)" in row for row in rows), "\n".join(lines)
