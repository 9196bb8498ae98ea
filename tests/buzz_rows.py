"""The engine tests that pin each row of firmware_spec/DECISIONS.md's "Differences from Buzz", for running them again
with a twin of the Python engine standing in (libvstig through ctypes, the compiled data path's Engine)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
_TEST = re.compile(r"`(tests/[\w/]+\.py)::(\w+)`")


def _pinned() -> list[tuple[str, str]]:
    text = (ROOT / "firmware_spec" / "DECISIONS.md").read_text(encoding="utf-8")
    section = text.split("## Differences from Buzz", 1)[1].split("\n## ", 1)[0]
    return sorted(set(_TEST.findall(section)))


PINNED = _pinned()  # (path, test name) of every row's test
ENGINE_TESTS = [(path, name) for path, name in PINNED if path.startswith("tests/unit/")]


def with_twins(path: str, prefix: str, **twins: object) -> ModuleType:
    """The test module at `path` loaded afresh (named `prefix` + its stem), its names in `twins` (Stigmergy,
    OutQueue) pointing at the twins, so its tests judge them with the same assertions."""
    spec = importlib.util.spec_from_file_location(f"{prefix}{Path(path).stem}", ROOT / path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name, twin in twins.items():
        if hasattr(module, name):
            setattr(module, name, twin)
    return module
