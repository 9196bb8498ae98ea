"""The ten lines of docs/how-to/python.md run verbatim against stand-in robots in another process."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[2]
DOC = ROOT / "docs" / "how-to" / "python.md"


def ten_lines(path: Path = DOC, heading: str = "Then the program:") -> str:
    text = path.read_text()
    section = text[text.index(heading):]
    match = re.search(r"```python\n(.*?)```", section, re.S)
    assert match is not None
    return match.group(1)


def test_the_ten_line_example_runs_verbatim_and_the_robots_agree(tmp_path: Path) -> None:
    code = ten_lines()
    assert len(code.splitlines()) == 10
    assert ten_lines(ROOT / "README.md", "## A taste of Python") == code  # the README shows the same lines
    robots = subprocess.Popen([sys.executable, "-m", "vstig_hw.api.virtual", "robots.pty"], cwd=tmp_path,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert robots.stdout is not None
        assert "20 robots play Figure 1 on serial:robots.pty?framing=cobs8" in robots.stdout.readline()
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                              timeout=60, check=False)
        assert done.returncode == 0, done.stderr
        assert done.stdout == "the swarm agrees on 40\n"
    finally:
        robots.send_signal(signal.SIGINT)
        out, err = robots.communicate(timeout=10)
    assert robots.returncode == 0, err
    assert "robots hold 40: 20" in out
    assert not (tmp_path / "robots.pty").exists()  # the link it made is gone


def test_the_stand_in_robots_never_replace_a_file(tmp_path: Path) -> None:
    (tmp_path / "robots.pty").write_text("mine")
    done = subprocess.run([sys.executable, "-m", "vstig_hw.api.virtual", "robots.pty"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=30, check=False)
    assert done.returncode == 2 and "robots.pty exists: name a path that does not" in done.stderr
    assert (tmp_path / "robots.pty").read_text() == "mine"
