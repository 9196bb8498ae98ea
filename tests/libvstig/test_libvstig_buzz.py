"""The Buzz differential against libvstig: every engine test that pins a row of firmware_spec/DECISIONS.md's
"Differences from Buzz" runs again, unchanged, with libvstig's engine and queue standing in for the Python ones.

Each test module is loaded afresh and its `Stigmergy` and `OutQueue` names point at the C twins (tests/libvstig/
clib.py), so the same assertions judge the C library; Python rules such as the tests' lambdas are called back
from C. The rows pinned by vector tests (tests/spec) run against C through the vectors.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from types import ModuleType

import pytest
from buzz_rows import ENGINE_TESTS, PINNED, ROOT, with_twins
from clib import COutQueue, CStigmergy, Lib


def test_every_row_runs_against_libvstig() -> None:
    """Rows pinned by engine tests run below; the rest are vector tests, which tests/spec runs against C too."""
    assert len(ENGINE_TESTS) >= 10
    vector_tests = {(path, name) for path, name in PINNED if path.startswith("tests/spec/")}
    assert set(PINNED) == set(ENGINE_TESTS) | vector_tests
    c_vectors = (ROOT / "tests" / "spec" / "test_spec_c_vectors.py").read_text(encoding="utf-8")
    for path, _ in vector_tests:
        for vectors in re.findall(r'load\("(\w+\.json)"\)', (ROOT / path).read_text(encoding="utf-8")):
            if vectors in ("wire.json", "receive.json"):
                assert f'load("{vectors}")' in c_vectors


def _with_libvstig(path: str, lib: Lib) -> ModuleType:
    return with_twins(path, "libvstig_twin_", Stigmergy=CStigmergy.on(lib), OutQueue=COutQueue.on(lib))


@pytest.mark.parametrize(("path", "name"), ENGINE_TESTS, ids=[name for _, name in ENGINE_TESTS])
def test_the_row_holds_for_libvstig(lib: Lib, path: str, name: str) -> None:
    module = _with_libvstig(path, lib)
    assert module.Stigmergy is not None and module.Stigmergy.__name__ == "CStigmergy"  # type: ignore[attr-defined]
    test: Callable[[], None] = getattr(module, name)
    test()
