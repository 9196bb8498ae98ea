"""Every program in examples/ runs as a subprocess against stand-in robots on real links, and checks its outcome."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).parents[2] / "examples"


@pytest.mark.parametrize(("example", "said"), [
    ("figure1.py", r"the PC holds 100; 30 of 30 robots hold 100"),
    ("area_tasks.py", "16 of 16 areas done"),
    ("supervisor.py", "8 robots sent home, 8 back"),
])
def test_the_example_runs_and_its_swarm_does_the_task(example: str, said: str) -> None:
    done = subprocess.run([sys.executable, str(EXAMPLES / example)], capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert said in done.stdout


def test_every_example_is_tested() -> None:
    assert sorted(path.name for path in EXAMPLES.glob("[!_]*.py")) == ["area_tasks.py", "figure1.py", "supervisor.py"]


def test_an_example_given_a_bad_link_says_so_in_one_line() -> None:
    done = subprocess.run([sys.executable, str(EXAMPLES / "figure1.py"), "radio:x"], capture_output=True, text=True,
                          timeout=60, check=False)
    assert done.returncode == 2 and "unknown kind 'radio'" in done.stderr and "Traceback" not in done.stderr
