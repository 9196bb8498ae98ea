"""No `vstig` a test started outlives it: one still running when the test ends is killed (and fails no other test
by holding its pty or port)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from peers import kill_what_tests_left_running


@pytest.fixture(autouse=True)
def _no_process_outlives_its_test() -> Iterator[None]:
    yield
    kill_what_tests_left_running()
