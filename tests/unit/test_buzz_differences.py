"""DECISIONS.md's table of differences from Buzz: every row names tests, and they exist."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DECISIONS = ROOT / "firmware_spec" / "DECISIONS.md"
_TEST = re.compile(r"`(tests/[\w/]+\.py)::(\w+)`")


def _rows() -> list[list[str]]:
    section = DECISIONS.read_text(encoding="utf-8").split("## Differences from Buzz", 1)[1].split("\n## ", 1)[0]
    lines = [line for line in section.splitlines() if line.startswith("|")]
    header, _separator, *rows = lines
    assert [cell.strip() for cell in header.strip("|").split("|")] == ["rule", "Buzz", "vstig-hw", "why", "pinned by"]
    return [[cell.strip() for cell in row.strip("|").split(" | ")] for row in rows]


def test_every_difference_is_pinned_by_tests_that_exist() -> None:
    rows = _rows()
    assert len(rows) >= 9
    for rule, buzz, ours, why, pinned in rows:
        assert rule and buzz and ours and why, rule
        tests = _TEST.findall(pinned)
        assert tests, f"difference {rule!r} names no test"
        for path, name in tests:
            tree = ast.parse((ROOT / path).read_text(encoding="utf-8"))
            defined = {node.name for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)}
            assert name in defined, f"difference {rule!r}: {path} has no test {name}"
