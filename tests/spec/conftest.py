"""Shared fixtures for the firmware_spec tests: the vectors, the compiled C driver, peer tools."""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pytest
from required import require_tool

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT / "firmware_spec"
VECTORS = SPEC / "vectors"
C_DIR = SPEC / "libvstig"
C_SOURCES = [*sorted(C_DIR.glob("vstig_*.c")), C_DIR / "tests" / "driver.c"]
STRICT_FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
BUILDS = {"strict": ["-O2"], "sanitized": ["-O1", "-g", "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]}


def load(name: str) -> Any:
    return json.loads((VECTORS / name).read_text(encoding="utf-8"))


class Driver:
    """The compiled libvstig test driver: one command per line in, one result per line out."""

    def __init__(self, exe: Path) -> None:
        self.exe = exe

    def run(self, commands: Iterable[str]) -> list[str]:
        lines = list(commands)
        env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:abort_on_error=1", UBSAN_OPTIONS="halt_on_error=1")
        done = subprocess.run([self.exe], input="".join(f"{c}\n" for c in lines), capture_output=True,
                              text=True, timeout=120, env=env, check=False)
        assert done.returncode == 0, f"{self.exe.name} failed ({done.returncode}): {done.stderr[-2000:]}"
        assert not done.stderr, f"{self.exe.name} complained: {done.stderr[-2000:]}"
        out = done.stdout.split("\n")[:-1]
        assert len(out) == len(lines), f"{len(lines)} commands gave {len(out)} lines"
        return out

    def one(self, command: str) -> str:
        return self.run([command])[0]


@pytest.fixture(scope="session", params=sorted(BUILDS))
def driver(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Driver:
    """The C driver built with the strict warning flags, plain and with ASan+UBSan."""
    gcc = require_tool("gcc")
    exe = tmp_path_factory.mktemp("c") / f"driver_{request.param}"
    done = subprocess.run([gcc, *STRICT_FLAGS, *BUILDS[request.param], "-I", str(C_DIR), "-o", str(exe),
                           *map(str, C_SOURCES)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, f"gcc {request.param} build failed:\n{done.stderr}"
    return Driver(exe)


def results(messages: list[str], drops: dict[str, int]) -> str:
    """A receive result in the driver's `msgs=... drops=...` form (drops in the header's reason order)."""
    order = ["cobs", "crc", "bad_length", "overlong", "bad_index", "collision", "check", "stale", "duplicate",
             "foreign_type", "bad_version", "error_frame", "unknown_id", "remote_frame", "bad_dlc", "op_mismatch",
             "noise", "escape", "frame_length", "truncated", "checksum", "unknown_type"]
    shown = [f"{name}:{drops[name]}" for name in order if drops.get(name)]
    assert set(drops) <= set(order), f"a vector names an unknown drop reason: {set(drops) - set(order)}"
    return f"msgs={','.join(messages) or '-'} drops={','.join(shown) or '-'}"


def can_id_fields(can_id: int, extended: bool) -> dict[str, int]:
    """The fields SPEC.md section 6.5 puts in an arbitration ID (default bases)."""
    if extended:
        return {"base": can_id & 0x1E000000, "stigmergy": (can_id >> 17) & 0xFF, "op": (can_id >> 16) & 1,
                "sender": can_id & 0xFFFF}
    return {"base": can_id & 0x600, "stigmergy": 0, "op": (can_id >> 8) & 1, "sender": can_id & 0xFF}
