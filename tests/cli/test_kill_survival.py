"""Captures outlive their recorder: SIGKILL keeps what was flushed, SIGHUP (a closed terminal) closes cleanly.

A recorder killed outright cannot close its file: an MCAP file then lacks its
summary and footer, a .gz stream its end marker. Each tick flushes what was
written (a whole MCAP chunk, a gzip sync point), and the readers read such a
file to its last complete record and report the cut in one line.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest
from peers import PtyPeer, SlcanAdapter, run_vstig, start_vstig, wait_for

from vstig_hw import Message, Op, encode
from vstig_hw.capture.records import CaptureError, Damage, read_capture
from vstig_hw.framing import make_serial_framing

MESSAGES = [Message(Op.PUT, 9, 100 + i, i + 1, 3) for i in range(20)]


def _recorded(capture: Path) -> int:
    """How many messages the (perhaps unfinished) capture holds now."""
    try:
        return sum(1 for _ in read_capture(str(capture), Damage(skip=True)))
    except (CaptureError, OSError):
        return 0


def _record_serial(capture: Path, radio: PtyPeer) -> subprocess.Popen[str]:
    """`vstig record` of an epuck4 radio into `capture`, once it has written all of MESSAGES there."""
    framing = make_serial_framing("epuck4")
    recorder = start_vstig("record", f"serial:{radio.path}?framing=epuck4", "-o", str(capture))
    wait_for(lambda: "recording" in (recorder.stderr.readline() if recorder.stderr else ""), 30)
    time.sleep(0.3)  # the port is open once the command says it records
    radio.write(b"".join(unit for msg in MESSAGES for unit in framing.encode(msg)))
    try:
        wait_for(lambda: _recorded(capture) == len(MESSAGES), 20)
    except AssertionError:
        recorder.kill()
        recorder.communicate()
        raise
    return recorder


def _values(stdout: str) -> list[int]:
    return [json.loads(line)["value"] for line in stdout.splitlines()]


def test_an_mcap_recording_killed_outright_keeps_every_flushed_message(tmp_path: Path) -> None:
    capture = tmp_path / "radio.mcap"
    radio = PtyPeer()
    try:
        recorder = _record_serial(capture, radio)
        recorder.kill()  # SIGKILL: no chance to finish the file
        recorder.communicate(timeout=10)
    finally:
        radio.close()
    expected = [m.value for m in MESSAGES]

    strict = run_vstig("decode", str(capture), "--format", "jsonl")
    assert _values(strict.stdout) == expected  # every complete chunk, before the error
    assert strict.returncode == 1
    damage = [line for line in strict.stderr.splitlines() if line]
    assert len(damage) == 1 and "cut short" in damage[0] and f"read all {len(MESSAGES)} messages" in damage[0]

    lenient = run_vstig("decode", str(capture), "--format", "jsonl", "--skip-bad")
    assert lenient.returncode == 0, lenient.stderr
    assert _values(lenient.stdout) == expected
    assert sum("cut short" in line for line in lenient.stderr.splitlines()) == 1

    analyzed = run_vstig("analyze", str(capture), "--skip-bad")
    assert analyzed.returncode == 0, analyzed.stderr
    assert analyzed.stdout.startswith(f"capture: {len(MESSAGES)} messages")

    table = run_vstig("replay", str(capture), "--table", "--skip-bad")
    assert table.returncode == 0, table.stderr
    assert f"{MESSAGES[-1].value}" in table.stdout and "cut short" in table.stderr


def test_sighup_closes_an_mcap_recording_like_sigterm(tmp_path: Path) -> None:
    capture = tmp_path / "radio.mcap"
    radio = PtyPeer()
    try:
        recorder = _record_serial(capture, radio)
        recorder.send_signal(signal.SIGHUP)  # the terminal it ran in was closed
        _out, err = recorder.communicate(timeout=20)
    finally:
        radio.close()
    assert recorder.returncode == 0, err
    assert re.search(rf"\d+ units? in {re.escape(str(capture))}", err)  # counters and summary printed on the way out
    whole = run_vstig("decode", str(capture), "--format", "jsonl")
    assert whole.returncode == 0, whole.stderr  # closed: summary and footer written, nothing cut
    assert _values(whole.stdout) == [m.value for m in MESSAGES]

    radio = PtyPeer()  # under nohup, SIGHUP stays ignored: the recorder outlives its terminal
    try:
        nohup = start_vstig("record", f"serial:{radio.path}", "-o", str(tmp_path / "kept.mcap"),
                            preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))
        wait_for(lambda: "recording" in (nohup.stderr.readline() if nohup.stderr else ""), 30)
        time.sleep(1.0)  # well into its run, where SIGHUP would stop it were it not ignored
        nohup.send_signal(signal.SIGHUP)
        time.sleep(1.0)
        still_running = nohup.poll() is None
        nohup.terminate()
        nohup.communicate(timeout=20)
    finally:
        radio.close()
    assert still_running and nohup.returncode == 0


# -- 1,000 frames/s on a CAN link, killed after ~2 s: every format against python-can's own logger -------------
FORMATS = [".log", ".asc", ".blf", ".csv", ".trc", ".log.gz", ".asc.gz", ".pcap", ".mcap"]
PYTHON_CAN_WRITES = {".log", ".asc", ".blf", ".csv", ".trc", ".log.gz", ".asc.gz"}
RATE = 1000  # frames per second
RUN = 2.0  # seconds of traffic before the kill
FLUSHED_WITHIN = 1.0  # seconds: a recorder that flushes every tick keeps what came this long before the kill
# Both recorders race the same SIGKILL on a shared 2-core machine: ours flushes each tick (0.1 s), so on a
# loaded machine it may stand up to one tick's frames behind a logger whose last write happened to land later.
ONE_TICK = RATE // 10


def _frame(i: int) -> can.Message:
    msg = Message(Op.PUT, i % 64, i & 0xFFFF, (i // 64 + 1) & 0xFFFF, 5)
    return can.Message(arbitration_id=0x605, data=encode(msg), is_extended_id=False)


def _start_both(tmp_path: Path, suffix: str) -> tuple[list[SlcanAdapter], list[subprocess.Popen[str]], list[Path]]:
    adapters = [SlcanAdapter(), SlcanAdapter()]
    ours, theirs = tmp_path / f"ours{suffix}", tmp_path / f"python-can{suffix}"
    commands = [["record", f"can:slcan:{adapters[0].path}", "-o", str(ours)]]
    processes = [start_vstig(*commands[0])]
    if suffix in PYTHON_CAN_WRITES:
        processes.append(subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "slcan", "-c", adapters[1].path,
                                           "-f", str(theirs)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                          text=True))
    return adapters[: len(processes)], processes, [ours, theirs][: len(processes)]


def _kept(path: Path) -> int:
    if not path.exists() or path.stat().st_size == 0:
        return 0
    done = run_vstig("decode", str(path), "--format", "jsonl", "--skip-bad")
    assert done.returncode == 0, done.stderr  # whatever the kill left decodes, the damage skipped
    return len(done.stdout.splitlines())


@pytest.mark.slow
@pytest.mark.parametrize("suffix", FORMATS)
def test_killed_at_1000_frames_a_second_every_format_keeps_what_python_can_keeps(tmp_path: Path,
                                                                                suffix: str) -> None:
    adapters, processes, paths = _start_both(tmp_path, suffix)
    try:
        wait_for(lambda: all("O" in a.commands or "L" in a.commands for a in adapters), 60)
        time.sleep(0.5)  # python-can's slcan driver reads only once its open has returned
        sent_by: list[float] = []  # when each frame was handed to both adapters
        stop = threading.Event()

        def traffic() -> None:
            start = time.monotonic()
            i = 0
            while not stop.is_set():
                due = start + i / RATE
                time.sleep(max(0.0, due - time.monotonic()))
                for adapter in adapters:
                    adapter.inject(_frame(i))
                sent_by.append(time.monotonic())
                i += 1

        sender = threading.Thread(target=traffic, daemon=True)
        sender.start()
        time.sleep(RUN)
        for process in processes:
            os.kill(process.pid, signal.SIGKILL)
        killed = time.monotonic()
        stop.set()
        sender.join(5)
        for process in processes:
            process.communicate(timeout=10)
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
        for adapter in adapters:
            adapter.close()
    kept = [_kept(path) for path in paths]
    if len(kept) > 1:
        assert kept[0] >= kept[1] - ONE_TICK, f"{suffix}: we kept {kept[0]} frames, python-can's logger {kept[1]}"
    if suffix != ".blf":  # BLF blocks are closed every 2 s (compression), not every tick
        long_before = sum(1 for t in sent_by if t < killed - FLUSHED_WITHIN)
        assert kept[0] >= long_before > 0, f"{suffix}: kept {kept[0]} of the {long_before} frames sent >1 s before"
