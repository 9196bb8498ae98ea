"""The import contracts of pyproject.toml ([tool.importlinter]) hold, and would catch a breach.

`make test` runs `lint-imports` on the tree (`make layers`). Here it runs on a copy of
the tree (the packages and pyproject.toml) three times: as it is (kept), with one
import that closes a cycle inside a package, and with one that reaches up a layer:
each breach must fail the run and be named in its report.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    """The packages under their import names, and the contracts (the cache kept out of the tree)."""
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(ROOT / "vstig_hw", tmp_path / "vstig_hw", ignore=ignore)
    shutil.copytree(ROOT / "cli", tmp_path / "vstig_cli", ignore=ignore)
    config = (ROOT / "pyproject.toml").read_text()
    (tmp_path / "pyproject.toml").write_text(config.replace(".venv/.import-linter-cache", str(tmp_path / "cache")))
    return tmp_path


def _lint(tree: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}  # the copy, not the installed tree, is what grimp reads
    return subprocess.run([str(LINT_IMPORTS), "--config", str(tree / "pyproject.toml")], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=120, check=False)


def _add_import(module: Path, line: str) -> None:
    module.write_text(module.read_text() + f"\n{line}\n")


def test_the_tree_keeps_its_contracts(tree: Path) -> None:
    done = _lint(tree)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "2 kept, 0 broken" in done.stdout


def test_a_cycle_inside_a_package_breaks_the_build(tree: Path) -> None:
    _add_import(tree / "vstig_hw" / "capture" / "records.py", "from .decoded import Decoder")
    done = _lint(tree)
    assert done.returncode == 1, done.stdout
    assert "No cycles are allowed in vstig_hw.capture" in done.stdout
    assert "1 kept, 1 broken" in done.stdout  # the layers still hold: only the cycle is new


def test_a_framing_that_imports_the_gateway_breaks_the_layers(tree: Path) -> None:
    _add_import(tree / "vstig_hw" / "framing" / "can.py", "from ..gateway import Node")
    done = _lint(tree)
    assert done.returncode == 1, done.stdout
    assert "vstig_hw.framing.can -> vstig_hw.gateway" in done.stdout
