"""The engine in ten lines (docs/explanation/protocol.md) runs and prints what its comments say."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

PAGE = Path(__file__).resolve().parents[2] / "docs" / "explanation" / "protocol.md"


def test_readme_engine_example_runs() -> None:
    section = PAGE.read_text().split("## The engine in ten lines", 1)[1]
    code = section.split("```python", 1)[1].split("```", 1)[0]
    assert len(code.strip().splitlines()) <= 10
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, str(PAGE), "exec"), {})
    assert out.getvalue().strip() == "[Message(PUT, key=7, value=1234, timestamp=1, robot=1)]"
