"""Runs test_socketcan.py inside User-Mode Linux, whose kernel has SocketCAN (this host's usually has not)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import uml


def _host_has_vcan() -> bool:
    return Path("/sys/class/net/vcan0").exists() and Path("/sys/class/net/vcan1").exists()


@pytest.mark.slow
@pytest.mark.socketcan
def test_socketcan_module_passes_inside_user_mode_linux(tmp_path: Path) -> None:
    if _host_has_vcan():
        pytest.skip("this host has vcan0 and vcan1: test_socketcan.py runs directly, no UML needed")
    reason = uml.unavailable_reason()
    if reason:
        if os.environ.get("VSTIG_REQUIRE_SOCKETCAN") == "1":
            pytest.fail(f"VSTIG_REQUIRE_SOCKETCAN=1 but {reason}")
        pytest.skip(reason)
    run = uml.run([uml.SOCKETCAN_MODULE, "-q"], tmp_path)
    assert run.exit_code == 0, run.explain()
    suite = ET.parse(run.junit).getroot().find("testsuite")
    assert suite is not None, run.explain()
    counts = {key: int(suite.get(key, "0")) for key in ("tests", "failures", "errors", "skipped")}
    assert counts["tests"] >= 5 and counts["failures"] == counts["errors"] == counts["skipped"] == 0, counts
