"""replay runs under SCHED_FIFO where permitted, keeps normal scheduling silently where not, and says which
with --verbose; the units go out either way."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from peers import VSTIG, PtyPeer

from vstig_hw.capture.replay import realtime_scheduling
from vstig_hw.capture.serial_log import HEADER

NO_SYS_NICE = ["setpriv", "--inh-caps=-sys_nice", "--bounding-set=-sys_nice"]


def _permitted() -> bool:
    try:
        os.sched_setscheduler(0, os.sched_getscheduler(0), os.sched_getparam(0))  # a no-op, to probe nothing
    except OSError:
        return False
    with realtime_scheduling() as what:
        return what.startswith("SCHED_FIFO")


def _replay(tmp_path: Path, *extra: str, prefix: tuple[str, ...] = ()) -> tuple[str, bytes]:
    capture = tmp_path / "two.cap"
    capture.write_text(f"{HEADER}\n(1700000000.000000) radio cobs8 rx 0a0b0c\n"
                       "(1700000000.010000) radio cobs8 rx 0d0e0f\n")
    radio = PtyPeer()
    try:
        done = subprocess.run([*prefix, VSTIG, "replay", str(capture), "--onto", f"serial:{radio.path}", *extra],
                              capture_output=True, text=True, timeout=60, check=False)
        got = b""
        while chunk := radio.read(0.3):
            got += chunk
    finally:
        radio.close()
    assert done.returncode == 0, done.stderr
    return done.stderr, got


def test_the_scheduling_is_restored_after_a_replay() -> None:
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    with realtime_scheduling(priority=7) as what:
        during = os.sched_getscheduler(0)
    assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before
    if what.startswith("SCHED_FIFO"):
        assert what == "SCHED_FIFO priority 7" and during == os.SCHED_FIFO
    else:
        assert what == "normal scheduling (SCHED_FIFO needs root or CAP_SYS_NICE)" and during == before[0]


def test_verbose_says_how_the_replay_ran_and_the_units_go_out(tmp_path: Path) -> None:
    err, got = _replay(tmp_path, "--verbose")
    expected = ("SCHED_FIFO priority 10" if _permitted()
                else "normal scheduling (SCHED_FIFO needs root or CAP_SYS_NICE)")
    assert f"replay thread: {expected}" in err
    assert got == bytes.fromhex("000a0b0c0d0e0f")  # the framing's preamble, then both units
    quiet, _ = _replay(tmp_path)
    assert "replay thread" not in quiet  # the fallback is silent without --verbose


@pytest.mark.skipif(shutil.which("setpriv") is None, reason="setpriv (util-linux) drops CAP_SYS_NICE for this test")
def test_without_cap_sys_nice_the_replay_falls_back_to_normal_scheduling(tmp_path: Path) -> None:
    import resource

    if resource.getrlimit(resource.RLIMIT_RTPRIO)[0] > 0:
        pytest.skip("RLIMIT_RTPRIO allows SCHED_FIFO without CAP_SYS_NICE here")
    err, got = _replay(tmp_path, "--verbose", prefix=tuple(NO_SYS_NICE))
    assert "replay thread: normal scheduling (SCHED_FIFO needs root or CAP_SYS_NICE)" in err
    assert got == bytes.fromhex("000a0b0c0d0e0f")  # the framing's preamble, then both units
