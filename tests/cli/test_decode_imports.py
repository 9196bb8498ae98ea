"""Decoding a candump log loads what a candump log needs: its reader, the decoder, the CAN framing.

A fresh interpreter (a subprocess, so nothing this test session imported counts) decodes
a two-line log and reports `sys.modules` and every `open` of the log (an audit hook): the
format is sniffed with one open and read with one more, through at most three capture
modules, and no transport, link, gateway, engine, dialect or numpy is imported.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

LOG = ("(1700000000.250000) can0 601#0003006400010001\n"
       "(1700000000.260000) can0 701#8003000000010002\n")
TEXT = ("(1700000000.250000) can0 id=601 PUT key=3 value=100 ts=1 robot=1 sender=1\n"
        "(1700000000.260000) can0 id=701 GET key=3 value=0 ts=1 robot=2 sender=1\n")
NEVER = ("vstig_hw.transports", "vstig_hw.links", "vstig_hw.gateway", "vstig_hw.engine", "vstig_hw.dialects",
         "numpy")

# Runs in the child: `log` and `report` are its argv; DECODE is the code under test.
_CHILD = """
import json, sys
log, report = sys.argv[1], sys.argv[2]
opens = []
sys.addaudithook(lambda event, args: opens.append(1) if event == "open" and str(args[0]) == log else None)
{decode}
with open(report, "w") as out:
    json.dump({{"modules": sorted(sys.modules), "opens": len(opens)}}, out)
"""
_LIBRARY = "from vstig_hw.capture.decoded import decode_file\ndecode_file(log, sys.stdout, 'text')"
_CLI = "from vstig_cli.main import run\nsys.argv = ['vstig', 'decode', log]\nrun()"


def _decode(tmp_path: Path, decode: str) -> tuple[str, dict[str, Any]]:
    log, report = tmp_path / "x.log", tmp_path / "report.json"
    log.write_text(LOG)
    done = subprocess.run([sys.executable, "-c", _CHILD.format(decode=decode), str(log), str(report)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    result: dict[str, Any] = json.loads(report.read_text())
    return done.stdout, result


def _loaded(modules: list[str], prefixes: tuple[str, ...]) -> list[str]:
    return [m for m in modules if m.startswith(prefixes)]


def test_a_candump_decode_walks_three_capture_modules_and_opens_the_log_twice(tmp_path: Path) -> None:
    out, seen = _decode(tmp_path, _LIBRARY)
    assert out == TEXT
    capture = _loaded(seen["modules"], ("vstig_hw.capture.",))
    assert sorted(capture) == ["vstig_hw.capture.candump", "vstig_hw.capture.decoded", "vstig_hw.capture.records"]
    assert not _loaded(seen["modules"], NEVER)
    assert seen["opens"] == 2  # one to sniff its format, one to read it


def test_vstig_decode_of_a_candump_log_loads_no_transport_link_engine_dialect_or_numpy(tmp_path: Path) -> None:
    out, seen = _decode(tmp_path, _CLI)
    assert out == TEXT
    assert not _loaded(seen["modules"], NEVER)
    # Beyond the three that decode: the filter and time-column options the command builds from its flags.
    assert set(_loaded(seen["modules"], ("vstig_hw.capture.",))) <= {
        "vstig_hw.capture.candump", "vstig_hw.capture.decoded", "vstig_hw.capture.records",
        "vstig_hw.capture.filters", "vstig_hw.capture.time_columns"}
