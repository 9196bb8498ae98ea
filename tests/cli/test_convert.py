"""`vstig decode -o FILE` converts captures into every format `record` writes, as real subprocesses.

A converted file must decode back to the same messages, link names and times;
where a format names no link, a second link is refused and the one link reads back as `can`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from peers import run_vstig

from vstig_hw import Message, Op, encode
from vstig_hw.framing import make_serial_framing

T0 = 1700000000.123456
# (seconds after T0, link, sender, message): two buses, names python-can cannot turn into channel numbers
TRAFFIC = [(0.0, "can0", 5, Message(Op.PUT, 3, 100, 1, 7)), (0.250003, "lab", 6, Message(Op.PUT, 3, 101, 2, 7)),
           (0.5, "can0", 5, Message(Op.GET, 4, 0, 0, 9)), (1.999999, "lab", 6, Message(Op.PUT, 8, 7, 3, 6))]


def _line(t: float, link: str, sender: int, msg: Message) -> str:
    return f"({T0 + t:.6f}) {link} {0x600 | int(msg.op) << 8 | sender:03X}#{encode(msg).hex().upper()}\n"


@pytest.fixture
def log(tmp_path: Path) -> Path:
    path = tmp_path / "two_buses.log"
    path.write_text("".join(_line(*row) for row in TRAFFIC))
    return path


def _rows(path: Path, *options: str) -> list[dict[str, object]]:
    done = run_vstig("decode", str(path), "--format", "jsonl", *options)
    assert done.returncode == 0, done.stderr
    return [json.loads(line) for line in done.stdout.splitlines()]


def _convert(*args: str) -> str:
    done = run_vstig("decode", *args)
    assert done.returncode == 0, done.stderr
    return done.stderr


@pytest.mark.parametrize("ext", [".log", ".log.gz", ".asc", ".asc.gz", ".blf", ".mcap"])
def test_every_format_that_names_links_converts_and_decodes_back_the_same(tmp_path: Path, log: Path,
                                                                          ext: str) -> None:
    out = tmp_path / f"converted{ext}"
    said = _convert(str(log), "-o", str(out))
    assert f"{out}: {len(TRAFFIC)} records from 1 file" in said and "1 files" not in said, said
    original, back = _rows(log), _rows(out)
    if ext == ".mcap":  # an MCAP capture holds messages: no CAN IDs
        original = [{k: v for k, v in row.items() if k != "can_id"} for row in original]
    assert back == original
    assert [(row["t"], row["link"]) for row in back] == [(round(T0 + t, 6), link) for t, link, _, _ in TRAFFIC]


@pytest.mark.parametrize("ext", [".blf", ".asc"])
def test_a_converted_file_converts_back_to_the_candump_log_it_came_from(tmp_path: Path, log: Path, ext: str) -> None:
    middle, back = tmp_path / f"middle{ext}", tmp_path / "back.log"
    _convert(str(log), "-o", str(middle))
    _convert(str(middle), "-o", str(back))
    # python-can's candump writer adds the direction (R) after each frame; the rest is the line we wrote
    assert [line.removesuffix(" R") for line in back.read_text().splitlines()] == log.read_text().splitlines()


@pytest.mark.parametrize(("ext", "unnamed"), [(".csv", "can"), (".pcap", "can"), (".trc", "1")])  # TRC: bus 1
def test_a_format_that_names_no_link_takes_one_link_and_refuses_a_second(tmp_path: Path, log: Path, ext: str,
                                                                         unnamed: str) -> None:
    out = tmp_path / f"one{ext}"
    converted = _convert(str(log), "--link", "lab", "-o", str(out))
    assert f"{out} names no link: decode reads its frames back as one unnamed link" in converted
    assert [(row["t"], row["link"], row["value"]) for row in _rows(out)] == [
        (row["t"], unnamed, row["value"]) for row in _rows(log, "--link", "lab")]

    both = tmp_path / f"both{ext}"
    done = run_vstig("decode", str(log), "-o", str(both))
    assert done.returncode == 1 and done.stderr.strip().splitlines() == [
        f"Error: {both}: a {ext} capture names no link: 'lab' cannot join 'can0' "
        "(use .log, .asc, .blf or .mcap, or keep one --link)"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([log.name, out.name])  # no half file left


def test_serial_captures_convert_filtered_and_never_into_a_can_log(tmp_path: Path) -> None:
    cobs8 = make_serial_framing("cobs8")
    radio = tmp_path / "radio.cap"
    radio.write_text("# vstig serial capture v1\n" + "".join(
        f"({T0 + t:.6f}) radio0 cobs8 rx {b''.join(cobs8.encode(m)).hex()}\n" for t, _, _, m in TRAFFIC))
    keys = tmp_path / "key3.cap"
    _convert(str(radio), "--key", "3", "-o", str(keys))
    assert [(row["link"], row["key"], row["value"]) for row in _rows(keys)] == [("radio0", 3, 100), ("radio0", 3, 101)]

    wrong = tmp_path / "radio.log"
    done = run_vstig("decode", str(radio), "-o", str(wrong))
    assert done.returncode == 1 and done.stderr.strip().splitlines() == [
        f"Error: {radio}: link radio0 holds serial chunks: {wrong} can hold only CAN frames "
        "(write a .mcap file to join them)"]
    assert not wrong.exists()
    piped = run_vstig("decode", "-", "-o", str(wrong), input=radio.read_text())  # spooled to a file first
    assert piped.returncode == 1 and piped.stderr.startswith("Error: <stdin>: link radio0 holds serial chunks")


def test_a_conversion_never_replaces_a_file_unless_told(tmp_path: Path, log: Path) -> None:
    out = tmp_path / "kept.blf"
    out.write_bytes(b"precious")
    out.chmod(0o640)
    done = run_vstig("decode", str(log), "-o", str(out))
    assert done.returncode == 2 and f"{out} exists: --overwrite replaces it" in done.stderr
    assert out.read_bytes() == b"precious"
    _convert(str(log), "-o", str(out), "--overwrite")
    assert len(_rows(out)) == len(_rows(log))
    assert out.stat().st_mode & 0o777 == 0o640  # the replaced file's permissions, not a temporary file's

    new = tmp_path / "new.asc"
    _convert(str(log), "-o", str(new))
    umask = os.umask(0)
    os.umask(umask)
    assert new.stat().st_mode & 0o777 == 0o666 & ~umask  # as record would create it


def test_candump_time_styles_in_text_lines(tmp_path: Path, log: Path) -> None:
    def times(style: str, *files: Path) -> list[str]:
        done = run_vstig("decode", *(str(f) for f in files or (log,)), "-t", style, env={**os.environ, "TZ": "UTC"})
        assert done.returncode == 0, done.stderr
        return [line.split(")")[0] + ")" for line in done.stdout.splitlines()]

    assert times("a") == [f"({T0 + t:.6f})" for t, _, _, _ in TRAFFIC]
    assert times("z") == ["(000.000000)", "(000.250003)", "(000.500000)", "(001.999999)"]
    assert times("d") == ["(000.000000)", "(000.250003)", "(000.249997)", "(001.499999)"]
    assert times("A") == ["(2023-11-14 22:13:20.123456)", "(2023-11-14 22:13:20.373459)",
                          "(2023-11-14 22:13:20.623456)", "(2023-11-14 22:13:22.123455)"]
    later = tmp_path / "later.log"
    later.write_text(_line(12.5, "can0", 5, Message(Op.PUT, 5, 1, 1, 1)))
    assert times("z", log, later)[-1] == "(012.500000)"  # one clock across the files, as one capture


@pytest.mark.parametrize(("args", "problem"), [
    (["-t", "d", "--format", "jsonl"], "--time styles the text lines' time column"),
    (["-t", "z", "-o", "x.log"], "--time styles the text lines' time column"),
    (["--format", "csv", "-o", "x.log"], "-o writes the format its extension names; --format csv prints to stdout"),
])
def test_time_styles_and_formats_that_print_are_usage_errors_with_o(log: Path, args: list[str],
                                                                    problem: str) -> None:
    done = run_vstig("decode", str(log), *args, cwd=log.parent)
    assert done.returncode == 2 and problem in done.stderr
    assert not (log.parent / "x.log").exists()


def test_record_refuses_two_links_into_a_capture_that_names_none(tmp_path: Path) -> None:
    out = tmp_path / "bus.pcap"
    done = run_vstig("record", "can:virtual:a", "can:virtual:b", "-o", str(out), "--for", "0.2")
    assert done.returncode == 2 and "a .pcap capture names no link, so 2 links would become one" in done.stderr
    assert not out.exists()
