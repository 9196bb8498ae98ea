"""No `vstig` a test started outlives it: one still running when the test ends is killed (and fails no other test
by holding its pty or port)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from peers import STARTED


@pytest.fixture(autouse=True)
def _no_process_outlives_its_test() -> Iterator[None]:
    yield
    while STARTED:
        process = STARTED.pop()
        if process.poll() is None:
            process.kill()
            process.communicate()
