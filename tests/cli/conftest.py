"""No `vstig` a test started outlives it: one still running when the test ends is killed (and fails no other test
by holding its pty or port)."""

from __future__ import annotations

from peers import no_process_outlives_its_test  # noqa: F401  (an autouse fixture: pytest finds it here)
