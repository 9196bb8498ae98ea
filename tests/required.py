"""The one rule for a test whose real peer is a program on the machine: skip naming it, or fail under CI."""

from __future__ import annotations

import os
import shutil

import pytest


def require_tool(tool: str, package: str | None = None) -> str:
    """The tool's path; skip when it is missing, fail instead under VSTIG_REQUIRE_PEERS=1."""
    path = shutil.which(tool)
    if path is None:
        what = f"{tool} ({package})" if package else tool
        reason = f"{what} is not installed (tests/sysdeps.sh installs it when run as root)"
        if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
            pytest.fail(f"VSTIG_REQUIRE_PEERS=1 but {reason}")
        pytest.skip(reason)
    return path
