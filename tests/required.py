"""The one rule for a test whose real peer is a program or library on the machine: skip naming what is missing,
or fail under VSTIG_REQUIRE_PEERS=1 (CI), where tests/sysdeps.sh must have installed it."""

from __future__ import annotations

import os
import shutil
from typing import NoReturn

import pytest


def missing(what: str) -> NoReturn:
    reason = f"{what} is not installed (tests/sysdeps.sh installs it when run as root)"
    if os.environ.get("VSTIG_REQUIRE_PEERS") == "1":
        pytest.fail(f"VSTIG_REQUIRE_PEERS=1 but {reason}")
    pytest.skip(reason)


def require_tool(tool: str, package: str | None = None) -> str:
    """The tool's path, or `missing` (naming its Debian package when that is another name)."""
    path = shutil.which(tool)
    if path is None:
        missing(f"{tool} ({package})" if package else tool)
    return path
