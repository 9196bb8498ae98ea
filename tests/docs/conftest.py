"""Counts the docs examples that ran and prints the count at the end of the test output."""

from __future__ import annotations

from typing import Any

from docs_blocks import EXECUTED


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if EXECUTED:
        terminalreporter.write_line(
            f"docs examples executed: {EXECUTED['python']} Python snippets, {EXECUTED['shell']} shell blocks "
            f"({EXECUTED['python'] + EXECUTED['shell']} in all)")
