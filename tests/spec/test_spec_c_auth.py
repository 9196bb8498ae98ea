"""libvstig's vstig_auth against vectors/auth.json (SPEC.md section 10), built strict and with ASan+UBSan."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from conftest import BUILDS, C_DIR, STRICT_FLAGS, Driver, load
from required import require_tool

VECTORS = load("auth.json")


@pytest.fixture(scope="module", params=sorted(BUILDS))
def auth_driver(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Driver:
    gcc = require_tool("gcc")
    exe = tmp_path_factory.mktemp("auth") / f"auth_{request.param}"
    done = subprocess.run([gcc, *STRICT_FLAGS, *BUILDS[request.param], "-I", str(C_DIR), "-o", str(exe),
                           str(C_DIR / "vstig_auth.c"), str(C_DIR / "tests" / "auth_driver.c")],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, f"gcc {request.param} build failed:\n{done.stderr}"
    return Driver(exe)


def test_robot_keys(auth_driver: Driver) -> None:
    cases = VECTORS["robot_keys"]
    got = auth_driver.run(f"key {VECTORS['master']} {case['robot']}" for case in cases)
    assert got == [case["key"] for case in cases]


def test_tags(auth_driver: Driver) -> None:
    keys = {case["robot"]: case["key"] for case in VECTORS["robot_keys"]}
    cases = VECTORS["tags"]
    got = auth_driver.run(f"tag {keys[c['signer']]} {c['stigmergy']} {c['message']} {c['epoch']}" for c in cases)
    assert got == [case["tag"] for case in cases]


def test_verdicts(auth_driver: Driver) -> None:
    keys = {case["robot"]: case["key"] for case in VECTORS["robot_keys"]}
    commands, expected = [], []
    for case in VECTORS["verify"]:
        record = bytes.fromhex(case["record"])
        writer = int.from_bytes(record[6:8], "big")
        epoch = int.from_bytes(record[8:12], "big")
        commands.append(f"ok {keys[writer]} {case['stigmergy']} {record[:8].hex()} {epoch} {record[12:].hex()}")
        expected.append("1" if case["verdict"] == "good" else "0")
    assert auth_driver.run(commands) == expected


def test_builds_for_the_avr_without_64_bit_arithmetic(tmp_path: Path) -> None:
    avr_gcc = require_tool("avr-gcc", "gcc-avr and avr-libc")
    obj = tmp_path / "vstig_auth.o"
    done = subprocess.run([avr_gcc, "-mmcu=atmega328p", *STRICT_FLAGS, "-Os", "-c", str(C_DIR / "vstig_auth.c"),
                           "-o", str(obj)], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    symbols = subprocess.run(["avr-nm", str(obj)], capture_output=True, text=True, timeout=60, check=True).stdout
    assert not re.search(r"__\w+di3\b", symbols), f"64-bit arithmetic helpers linked in:\n{symbols}"
