"""How every `vstig` run ends, as the installed script: one line per failure, quiet pipes, no tracebacks."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

VSTIG = str(Path(sys.executable).with_name("vstig"))


def _shell(command: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=timeout, check=False)


def _one_line(text: str) -> str:
    assert "Traceback" not in text and "Exception ignored" not in text, text
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


@pytest.mark.parametrize("args", ["links", "--help", "sim --robots 3 --runs 1 --json", "decode --help"])
def test_a_full_stdout_is_one_line_and_exit_1(args: str) -> None:
    done = _shell(f"{VSTIG} {args} > /dev/full")
    assert done.returncode == 1
    assert _one_line(done.stderr) == "Error: cannot write to stdout: No space left on device"


def test_a_closed_stdout_is_one_line_and_exit_1_not_lost_output() -> None:
    done = _shell(f"{VSTIG} links >&-")
    assert done.returncode == 1 and _one_line(done.stderr) == "Error: cannot write to stdout: it is closed"


def _candump_log(path: Path, frames: int) -> None:
    lines = (f"({1700000000 + i / 1000:.6f}) can0 6{i % 128:02X}#{i % 3000:04X}0001{i % 60000 + 1:04X}0007\n"
             for i in range(frames))
    path.write_text("".join(lines))


@pytest.mark.parametrize("fmt", ["jsonl", "text", "csv"])
def test_piping_into_head_ends_quietly_with_status_0(tmp_path: Path, fmt: str) -> None:
    log = tmp_path / "big.log"
    _candump_log(log, 20000)  # far more than a pipe holds: decode is still writing when head leaves
    done = _shell(f"{VSTIG} decode {log} --format {fmt} | head -1; exit ${{PIPESTATUS[0]}}")
    assert done.returncode == 0, done.stderr
    assert len(done.stdout.splitlines()) == 1 and done.stderr == ""


def test_a_closed_stderr_does_not_stop_the_work(tmp_path: Path) -> None:
    log = tmp_path / "small.log"
    _candump_log(log, 3)
    done = _shell(f"{VSTIG} decode {log} --format jsonl 2>&-")
    assert done.returncode == 0 and len(done.stdout.splitlines()) == 3 and done.stderr == ""


@pytest.mark.parametrize(("folder", "says"), [("/proc/vstig-edges", "No such file or directory"),
                                              ("/sys/vstig-edges", "Operation not permitted"),
                                              ("/dev/full", "exists")])
def test_bad_output_folders_are_one_line_naming_the_path(folder: str, says: str) -> None:
    done = _shell(f"{VSTIG} sim paper --runs 1 --robots 10 -o {folder}")
    line = _one_line(done.stderr)
    assert done.returncode == 1 and folder in line and says in line, line


def test_decode_reads_stdin_and_pipes_and_tells_the_type_by_content(tmp_path: Path) -> None:
    log = tmp_path / "small.log"
    _candump_log(log, 3)
    for command in (f"cat {log} | {VSTIG} decode -", f"{VSTIG} decode /dev/stdin < {log}",
                    f"{VSTIG} decode <(cat {log})", f"cat {log} | {VSTIG} decode - --input-format log"):
        done = _shell(command)
        assert done.returncode == 0 and len(done.stdout.splitlines()) == 3, (command, done.stderr)
    done = _shell(f"echo garbage | {VSTIG} decode -")
    assert done.returncode == 2 and "<stdin>: cannot tell the capture type" in done.stderr
    bad = tmp_path / "bad.log"
    bad.write_text("(1.000000) can0 600#0001000200030004\nnot a frame\n")
    done = _shell(f"cat {bad} | {VSTIG} decode -")
    assert done.returncode == 1 and "Error: <stdin>:2: not a candump line" in _one_line(done.stderr)


def _sigint_as_a_terminal_has_it() -> None:
    """In the child: SIGINT as a foreground job has it, even when the tests run as a background job (which
    ignores it, and vstig rightly keeps it ignored)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_ends_a_command_quietly_with_status_130() -> None:
    import os
    import signal
    import time

    # As a terminal delivers it: to the whole process group, simulation workers included.
    sim = subprocess.Popen([VSTIG, "sim", "--robots", "2000", "--runs", "400", "--workers", "2"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                           preexec_fn=_sigint_as_a_terminal_has_it)
    time.sleep(3)
    os.killpg(sim.pid, signal.SIGINT)
    _, err = sim.communicate(timeout=60)
    assert sim.returncode == 130 and err.strip() == "", err


def test_sniff_jsonl_into_head_ends_quietly_with_status_0() -> None:
    import threading
    import time

    from peers import PtyPeer

    from vstig_hw import Message, Op
    from vstig_hw.framing import make_serial_framing

    radio = PtyPeer()
    cobs8 = make_serial_framing("cobs8")
    burst = b"".join(unit for i in range(50) for unit in cobs8.encode(Message(Op.PUT, 3, i, i + 1, 7)))
    stop = threading.Event()

    def robot() -> None:
        while not stop.is_set():
            radio.write(burst)
            time.sleep(0.01)

    threading.Thread(target=robot, daemon=True).start()
    try:
        done = _shell(f"{VSTIG} sniff serial:{radio.path} --jsonl | head -2; exit ${{PIPESTATUS[0]}}", timeout=60)
    finally:
        stop.set()
        time.sleep(0.05)
        radio.close()
    assert done.returncode == 0 and len(done.stdout.splitlines()) == 2 and done.stderr == "", done.stderr


def test_decode_from_stdin_into_mcap(tmp_path: Path) -> None:
    log = tmp_path / "small.log"
    _candump_log(log, 3)
    bag = tmp_path / "out.mcap"
    done = _shell(f"cat {log} | {VSTIG} decode - --format mcap -o {bag}")
    assert done.returncode == 0, done.stderr
    back = _shell(f"{VSTIG} decode {bag} --format jsonl")
    assert back.returncode == 0 and len(back.stdout.splitlines()) == 3, back.stderr
