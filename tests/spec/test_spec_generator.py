"""The vector generator is independent of vstig_hw and reproduces the committed vectors."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from conftest import SPEC, VECTORS

TOOLS = SPEC / "tools"


def test_tools_never_import_the_code_they_check() -> None:
    for script in TOOLS.glob("*.py"):
        for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            assert not any(name.split(".")[0] in ("vstig_hw", "vstig_cli", "cobs", "can", "construct")
                           for name in names), f"{script.name} imports {names}"


def test_generator_reproduces_committed_vectors(tmp_path: Path) -> None:
    # -I -S: no site-packages, no working directory: the standard library alone.
    subprocess.run([sys.executable, "-I", "-S", str(TOOLS / "make_vectors.py"), str(tmp_path)], check=True, timeout=120)
    written = sorted(p.name for p in tmp_path.glob("*.json"))
    assert written, "the generator wrote nothing"
    for name in written:
        assert (tmp_path / name).read_text(encoding="utf-8") == (VECTORS / name).read_text(encoding="utf-8"), name
