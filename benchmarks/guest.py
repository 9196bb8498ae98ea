"""Benchmarks that need SocketCAN run inside User-Mode Linux when this host has no vcan (tests/socketcan/uml.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def run_in_guest(module: str, out: Path, timeout: float) -> Any:
    """Boot a guest that runs `python -m benchmarks.<module> OUT` with vcan0 and vcan1; what it wrote to
    OUT/figures.json. RuntimeError (saying why) when no guest can boot or the program failed."""
    sys.path.insert(0, str(REPO / "tests" / "socketcan"))
    import uml  # type: ignore[import-not-found]

    reason = uml.unavailable_reason()
    if reason:
        raise RuntimeError(f"no vcan here and no User-Mode Linux to make one: {reason}")
    run = uml.run([], out, program=[sys.executable, "-m", f"benchmarks.{module}", str(out)], timeout=timeout)
    if run.exit_code != 0:
        raise RuntimeError(run.explain())
    return json.loads((out / "figures.json").read_text())
