"""record never destroys a capture: the link opens first, existing files need --overwrite or --append."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import can
import pytest
from click.testing import CliRunner
from peers import PtyPeer

from vstig_cli.main import cli
from vstig_hw.capture.records import read_capture

OLD = "(1700000000.000000) can0 605#0005000100010007\n"


def _record(*args: str, frames: int = 0, channel: str = "") -> tuple[int, str]:
    """Run `vstig record` in-process; with `frames`, a peer on the virtual bus sends that many meanwhile."""
    stop = threading.Event()

    def peer() -> None:
        with can.Bus(interface="virtual", channel=channel) as bus:
            sent = 0
            while sent < frames and not stop.is_set():
                time.sleep(0.3)  # give record time to open its end of the bus
                for _ in range(frames - sent):
                    bus.send(can.Message(arbitration_id=0x603, data=bytes([0, 3, 0, 9, 0, 1, 0, 3]),
                                         is_extended_id=False))
                    sent += 1

    thread = threading.Thread(target=peer, daemon=True)
    if frames:
        thread.start()
    result = CliRunner().invoke(cli, ["record", *args])
    stop.set()
    return result.exit_code, result.output


@pytest.mark.parametrize(("link", "name"), [("serial:/dev/vstig-edges-no-such-port", "keep.cap"),
                                            ("can:socketcan:vstigedges9", "keep.log"),
                                            ("can:socketcan:vstigedges9", "keep.blf")])
def test_a_link_that_does_not_open_leaves_the_file_alone(tmp_path: Path, link: str, name: str) -> None:
    keep = tmp_path / name
    keep.write_bytes(b"precious")
    code, output = _record(link, "-o", str(keep), "--overwrite", "--for", "0.2")
    assert code == 1 and "Traceback" not in output
    assert keep.read_bytes() == b"precious"


def test_an_existing_file_is_refused_in_one_line_unless_asked(tmp_path: Path) -> None:
    keep = tmp_path / "keep.log"
    keep.write_text(OLD)
    code, output = _record("can:virtual:vstig-edges-refuse", "-o", str(keep), "--for", "0.2")
    assert code == 2 and f"{keep} exists: --overwrite replaces it, --append adds to it" in output
    assert keep.read_text() == OLD
    code, output = _record("can:virtual:vstig-edges-refuse", "-o", str(keep), "--overwrite", "--append")
    assert code == 2 and "not both" in output


def test_append_keeps_what_was_there_and_adds_the_new_frames(tmp_path: Path) -> None:
    keep = tmp_path / "keep.log"
    keep.write_text(OLD)
    code, output = _record("can:virtual:vstig-edges-append", "-o", str(keep), "--append", "--for", "1.5",
                           frames=3, channel="vstig-edges-append")
    assert code == 0, output
    assert keep.read_text().startswith(OLD)
    ids = [r.unit.arbitration_id for r in read_capture(str(keep))]
    assert ids == [0x605, 0x603, 0x603, 0x603]


def test_overwrite_replaces(tmp_path: Path) -> None:
    keep = tmp_path / "keep.log"
    keep.write_text(OLD)
    code, output = _record("can:virtual:vstig-edges-over", "-o", str(keep), "--overwrite", "--for", "0.2")
    assert code == 0, output
    assert OLD not in keep.read_text()


def test_a_folder_or_no_output_gets_a_new_timestamped_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    code, output = _record("can:virtual:vstig-edges-auto", "-o", str(tmp_path), "--for", "0.1")
    assert code == 0, output
    code, output = _record("can:virtual:vstig-edges-auto", "-o", str(tmp_path), "--for", "0.1")
    assert code == 0, output
    made = sorted(p.name for p in tmp_path.iterdir())
    assert len(made) == 2 and all(n.startswith("vstig-vstig-edges-auto-20") and n.endswith(".log") for n in made)
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    radio = PtyPeer()
    try:
        code, output = _record(f"serial:{radio.path}", "--for", "0.1")
    finally:
        radio.close()
    assert code == 0, output
    (made_here,) = here.iterdir()
    assert made_here.name.startswith(f"vstig-{Path(radio.path).name}-20") and made_here.suffix == ".cap"


def test_rotation_skips_numbered_files_that_exist(tmp_path: Path) -> None:
    from vstig_hw.capture.files import RotatingCapture
    from vstig_hw.capture.records import Record

    (tmp_path / "r_001.cap").write_text("older run")
    capture = RotatingCapture(str(tmp_path / "r.cap"), "serial", max_bytes=100)
    for i in range(200):
        capture.write(Record(float(i), "radio", "cobs8", b"\x01\x02"))
    capture.close()
    assert (tmp_path / "r_001.cap").read_text() == "older run"
    assert capture.files[1].endswith("r_002.cap")


def test_a_file_that_cannot_take_the_capture_is_named(tmp_path: Path) -> None:
    radio = PtyPeer()
    try:
        code, output = _record(f"serial:{radio.path}", "-o", "/dev/full", "--for", "1")
    finally:
        radio.close()
    assert code == 1 and "/dev/full: No space left on device" in output and "Traceback" not in output
