"""Framings stay pure: no framing module imports a transport, a link or an I/O library."""

from __future__ import annotations

from pathlib import Path

import pytest
from module_imports import imports_of

import vstig_hw.framing

FRAMING_DIR = Path(vstig_hw.framing.__file__).parent
FORBIDDEN = ("vstig_hw.transports", "vstig_hw.links", "vstig_hw.gateway", "serial")


@pytest.mark.parametrize("path", sorted(FRAMING_DIR.glob("*.py")), ids=lambda p: p.name)
def test_framing_imports_no_transport_or_link(path: Path) -> None:
    bad = sorted(name for name in imports_of(path, "vstig_hw.framing")
                 if any(name == f or name.startswith(f + ".") for f in FORBIDDEN))
    assert not bad, f"{path.name} imports {bad}"
