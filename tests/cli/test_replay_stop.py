"""replay onto a real pty: Ctrl-C, SIGTERM or SIGHUP in a long gap ends it at once and nothing more is sent."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
from peers import PtyPeer, run_vstig, run_vstig_on_a_terminal_stderr, start_vstig, wait_for

from vstig_hw.capture.serial_log import HEADER


def _two_units(path: Path, gap: float) -> None:
    path.write_text(f"{HEADER}\n(1700000000.000000) radio cobs8 rx 0a0b0c\n"
                    f"({1700000000 + gap:.6f}) radio cobs8 rx 0d0e0f\n")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_in_a_long_gap_stops_at_once_and_sends_nothing_more(tmp_path: Path, sig: int) -> None:
    capture = tmp_path / "gap.cap"
    _two_units(capture, gap=3600.0)
    radio = PtyPeer()
    try:
        replayer = start_vstig("replay", str(capture), "--onto", f"serial:{radio.path}")
        got = b""

        def first_arrived() -> bool:
            nonlocal got
            got += radio.read(0.1)
            return bytes.fromhex("0a0b0c") in got

        wait_for(first_arrived, 30)
        replayer.send_signal(sig)
        began = time.monotonic()
        try:
            _out, err = replayer.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            replayer.kill()
            replayer.communicate()
            pytest.fail(f"replay ignored signal {sig} in a one-hour gap")
        assert time.monotonic() - began < 20
        assert replayer.returncode == 0 and "stopped by a signal" in err  # links closed, counters printed
        got += radio.read(0.5)
        assert bytes.fromhex("0d0e0f") not in got
    finally:
        radio.close()


def test_skip_gaps_and_ignore_timestamps_send_everything_without_the_wait(tmp_path: Path) -> None:
    capture = tmp_path / "gap.cap"
    _two_units(capture, gap=3600.0)
    for option in (["--skip-gaps", "0.2"], ["--ignore-timestamps"]):
        radio = PtyPeer()
        try:
            done = run_vstig("replay", str(capture), "--onto", f"serial:{radio.path}", *option, timeout=60)
            assert done.returncode == 0, done.stderr
            got = b""
            while bytes.fromhex("0d0e0f") not in got:
                chunk = radio.read(1.0)
                assert chunk, f"{option}: the second unit never came"
                got += chunk
            assert got.lstrip(b"\0") == bytes.fromhex("0a0b0c0d0e0f")  # after the link's resync byte(s)
        finally:
            radio.close()


def test_options_that_replay_onto_a_link_are_refused_with_table(tmp_path: Path) -> None:
    capture = tmp_path / "gap.cap"
    _two_units(capture, gap=1.0)
    done = run_vstig("replay", str(capture), "--table", "--loop")
    assert done.returncode == 2 and "--loop go with --onto, not --table" in done.stderr


def test_record_and_replay_show_a_live_counter_line_on_a_terminal(tmp_path: Path) -> None:
    code, shown = run_vstig_on_a_terminal_stderr("record", "can:virtual:vstig-edges-live",
                                                 "-o", str(tmp_path / "x.log"), "--for", "1.2")
    assert code == 0 and b"\r\x1b[K0 units" in shown, shown
    capture = tmp_path / "gap.cap"
    _two_units(capture, gap=0.2)
    radio = PtyPeer()
    try:
        code, shown = run_vstig_on_a_terminal_stderr("replay", str(capture), "--onto", f"serial:{radio.path}")
    finally:
        radio.close()
    assert code == 0 and b"\r\x1b[Ksent 1 unit " in shown, shown


def test_replay_onto_another_can_id_scheme_re_encodes_in_its_ids(tmp_path: Path) -> None:
    import can
    from click.testing import CliRunner

    from vstig_cli.main import cli

    capture = tmp_path / "swarm.log"
    capture.write_text("(1.000000) can0 603#0005006400010003\n(1.001000) can0 603#0005006400010003\n")
    with can.Bus(interface="virtual", channel="vstig-edges-ext") as listener:
        targets = (("can:virtual:vstig-edges-ext?extended=1", True), ("can:virtual:vstig-edges-ext", False))
        for spec, extended in targets:
            result = CliRunner().invoke(cli, ["replay", str(capture), "--onto", spec, "--robot-id", "9"])
            assert result.exit_code == 0, result.output
            frames = [listener.recv(2.0) for _ in range(2)]
            assert all(f is not None and f.is_extended_id == extended for f in frames), (spec, frames)
            assert all(f is not None and f.data == bytes.fromhex("0005006400010003") for f in frames)


def test_loop_says_once_how_many_passes_it_made(tmp_path: Path) -> None:
    capture = tmp_path / "short.cap"
    _two_units(capture, gap=0.05)
    radio = PtyPeer()
    try:
        replayer = start_vstig("replay", str(capture), "--onto", f"serial:{radio.path}", "--loop")
        got = b""

        def looped() -> bool:
            nonlocal got
            got += radio.read(0.1)
            return got.count(bytes.fromhex("0d0e0f")) >= 3

        wait_for(looped, 30)
        replayer.send_signal(signal.SIGTERM)
        _, err = replayer.communicate(timeout=20)
    finally:
        radio.close()
    summary = [line for line in err.splitlines() if line.startswith("sent ")]
    assert replayer.returncode == 0 and len(summary) == 1 and " passes" in summary[0], err
