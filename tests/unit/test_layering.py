"""Framings stay pure: no framing module imports a transport, a link or an I/O library."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import vstig_hw.framing

FRAMING_DIR = Path(vstig_hw.framing.__file__).parent
FORBIDDEN = ("vstig_hw.transports", "vstig_hw.links", "vstig_hw.gateway", "serial")


def _imports(path: Path) -> set[str]:
    """Absolute names of every module `path` imports (relative imports resolved against vstig_hw.framing)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names.add(node.module or "")
            else:
                base = "vstig_hw.framing".rsplit(".", node.level - 1)[0]
                names.add(f"{base}.{node.module}" if node.module else base)
    return names


@pytest.mark.parametrize("path", sorted(FRAMING_DIR.glob("*.py")), ids=lambda p: p.name)
def test_framing_imports_no_transport_or_link(path: Path) -> None:
    bad = sorted(name for name in _imports(path)
                 if any(name == f or name.startswith(f + ".") for f in FORBIDDEN))
    assert not bad, f"{path.name} imports {bad}"
