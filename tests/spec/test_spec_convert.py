"""Files `vstig decode -o` converts open in the tools labs use for each format.

python-can's readers (ASC, BLF, CSV, TRC, our pcap), can-utils (`asc2log`, `log2asc`),
tshark (pcap, BLF) and cantools (candump logs) read the converted frames with their
IDs, data, times, and for ASC and BLF one channel number per link.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import pytest
from conftest import SPEC, require_tool

from vstig_hw import Message, Op, encode

VSTIG = str(Path(sys.executable).with_name("vstig"))
T0 = 1700000000.123456
FRAMES = [(T0 + 0.25 * i + 1e-6 * i, "can0" if i % 2 == 0 else "lab",
           can.Message(arbitration_id=0x600 | 5 + i % 2, data=encode(Message(Op.PUT, 3 + i, 100 + i, i + 1, 7)),
                       is_extended_id=False)) for i in range(6)]


@pytest.fixture
def log(tmp_path: Path) -> Path:
    path = tmp_path / "two_buses.log"
    path.write_text("".join(f"({t:.6f}) {link} {f.arbitration_id:03X}#{bytes(f.data).hex().upper()}\n"
                            for t, link, f in FRAMES))
    return path


def _convert(source: Path, out: Path, *options: str) -> Path:
    done = subprocess.run([VSTIG, "decode", str(source), "-o", str(out), *options], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    return out


def _tool(*command: str, stdin: Path | None = None) -> str:
    done = subprocess.run(command, input=stdin.read_text() if stdin else None, capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize(("ext", "tolerance"), [(".asc", 1e-3), (".blf", 1e-6), (".csv", 1e-6), (".trc", 1e-6),
                                                (".pcap", 1e-6)])
def test_python_can_reads_the_converted_frames(tmp_path: Path, log: Path, ext: str, tolerance: float) -> None:
    one_link = ext in (".csv", ".trc", ".pcap")
    out = _convert(log, tmp_path / f"out{ext}", *(("--link", "can0") if one_link else ()))
    wanted = [(t, link, f) for t, link, f in FRAMES if not one_link or link == "can0"]
    options = {"relative_timestamp": False} if ext == ".asc" else {}  # ASC dates its trigger block to the ms
    frames = list(can.LogReader(str(out), **options))
    assert [(f.arbitration_id, bytes(f.data)) for f in frames] == [(f.arbitration_id, bytes(f.data))
                                                                   for _, _, f in wanted]
    assert all(abs(f.timestamp - t) <= tolerance for f, (t, _, _) in zip(frames, wanted, strict=True))
    if not one_link:  # one channel number per link, in order of appearance
        assert [f.channel for f in frames] == [0 if link == "can0" else 1 for _, link, _ in wanted]


def test_asc2log_reads_a_converted_asc_one_interface_per_link(tmp_path: Path, log: Path) -> None:
    asc = _convert(log, tmp_path / "out.asc")
    lines = _tool(require_tool("asc2log"), "-I", str(asc)).splitlines()
    # asc2log dates frames by the file's header, not ours: compare interfaces and frames
    assert [line.split()[1:3] for line in lines] == [
        ["can0" if link == "can0" else "can1", f"{f.arbitration_id:03X}#{bytes(f.data).hex().upper()}"]
        for _, link, f in FRAMES]


def test_log2asc_reads_a_candump_log_converted_from_blf(tmp_path: Path, log: Path) -> None:
    back = _convert(_convert(log, tmp_path / "out.blf"), tmp_path / "back.log")
    asc = _tool(require_tool("log2asc"), "-I", str(back), "can0", "lab")
    events = [line.split() for line in asc.splitlines() if line[:1] == " "]
    assert [(e[1], e[2], " ".join(e[6:])) for e in events] == [
        ("1" if link == "can0" else "2", f"{f.arbitration_id:X}", bytes(f.data).hex(" ").upper())
        for _, link, f in FRAMES]
    assert [float(e[0]) for e in events] == pytest.approx([t - T0 for t, _, _ in FRAMES], abs=1e-6)


@pytest.mark.parametrize("ext", [".pcap", ".blf"])
def test_tshark_reads_the_converted_frames(tmp_path: Path, log: Path, ext: str) -> None:
    out = _convert(log, tmp_path / f"out{ext}", *(("--link", "can0") if ext == ".pcap" else ()))
    wanted = [(t, f) for t, link, f in FRAMES if ext == ".blf" or link == "can0"]
    rows = _tool(require_tool("tshark"), "-r", str(out), "-T", "fields", "-e", "frame.time_epoch", "-e", "can.id",
                 "-e", "can.len").splitlines()
    assert [(int(r.split("\t")[1]), int(r.split("\t")[2])) for r in rows] == [(f.arbitration_id, len(f.data))
                                                                              for _, f in wanted]
    assert [float(r.split("\t")[0]) for r in rows] == pytest.approx([t for t, _ in wanted], abs=1e-6)


def test_cantools_decodes_a_candump_log_converted_from_asc(tmp_path: Path, log: Path) -> None:
    back = _convert(_convert(log, tmp_path / "out.asc"), tmp_path / "back.log")
    cantools = str(Path(sys.executable).with_name("cantools"))
    shown = _tool(cantools, "decode", "--frame-id-mask", "0x1E010700", str(SPEC / "vstig.dbc"),
                  "--single-line", stdin=back)
    assert [line.split(" :: ")[0].split()[1] for line in shown.splitlines()] == [link for _, link, _ in FRAMES]
    assert all(f"key: {3 + i}" in line and f"value: {100 + i}" in line for i, line in enumerate(shown.splitlines()))
