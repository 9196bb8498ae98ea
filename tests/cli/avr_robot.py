"""A robot firmware on a simulated ATmega328P (simavr), its UART on a pty: a real peer for `vstig bridge`.

The firmware is libvstig's example (firmware_spec/libvstig/examples/avr_robot.c), built by libvstig's own
Makefile with avr-gcc; the board is tests/cli/simavr_pty.c, built against Debian's libsimavr. Both are built
once per test session into a temporary folder.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from required import missing, require_tool

ROOT = Path(__file__).resolve().parents[2]
LIBVSTIG = ROOT / "firmware_spec" / "libvstig"
BOARD = Path(__file__).with_name("simavr_pty.c")
SIMAVR_HEADER = Path("/usr/include/simavr/sim_avr.h")


def _run(argv: list[str]) -> None:
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, f"{' '.join(argv)} failed:\n{done.stdout[-2000:]}{done.stderr[-3000:]}"


def build(folder: Path, keys: int = 16, robot_key: Path | None = None) -> tuple[Path, Path]:
    """(the firmware's ELF, the board program); skips, or fails under VSTIG_REQUIRE_PEERS=1, without the tools.
    `robot_key`: its own key as `vstig keys --format c` prints it, to tag its writes (SPEC.md section 10)."""
    make, gcc = require_tool("make"), require_tool("gcc")
    require_tool("avr-gcc", "gcc-avr and avr-libc")
    if not SIMAVR_HEADER.exists():
        missing(f"simavr's library and headers ({SIMAVR_HEADER}, libsimavr-dev)")
    signed = [f"ROBOT_KEY={robot_key}"] if robot_key is not None else []
    _run([make, "-s", "-C", str(LIBVSTIG), f"BUILD={folder}", f"KEYS={keys}", *signed, "robot"])
    board = folder / "simavr_pty"
    _run([gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", "-o", str(board), str(BOARD), "-lsimavr"])
    return folder / "avr" / "avr_robot.elf", board


class AvrRobot:
    """One simulated robot: `spec` is the link spec of its radio, for the bridge to open."""

    def __init__(self, built: tuple[Path, Path], robot_id: int) -> None:
        firmware, board = built
        self.id = robot_id
        self.process = subprocess.Popen([str(board), str(firmware), str(robot_id)], stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, text=True)
        self.path = ""
        assert self.process.stdout is not None
        for line in self.process.stdout:  # simavr's loader says a word first
            if line.startswith("/dev/"):
                self.path = line.strip()
                break
        assert self.path, f"the board printed no pty: {self.process.stderr.read() if self.process.stderr else ''}"
        self.spec = f"serial:{self.path}?framing=cobs8"

    def close(self) -> str:
        """Stop the board; returns what it said on stderr."""
        self.process.terminate()
        try:
            _out, err = self.process.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            _out, err = self.process.communicate()
            pytest.fail(f"the simavr board ignored SIGTERM: {err[-2000:]}")
        return err
