"""These tests share tests/cli's process helpers, and its rule: no `vstig` a test started outlives it."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cli"))
from peers import no_process_outlives_its_test  # noqa: F401  (an autouse fixture: pytest finds it here)
