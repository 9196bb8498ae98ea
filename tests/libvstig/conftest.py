"""libvstig built for the tests: as a gateway would hold it (every key, 32768 places) and as a small robot
would (4 places, so every table can be filled)."""

from __future__ import annotations

import pytest
from clib import Lib, build
from required import require_tool


@pytest.fixture(scope="session")
def gcc() -> str:
    return require_tool("gcc")


@pytest.fixture(scope="session")
def lib(gcc: str, tmp_path_factory: pytest.TempPathFactory) -> Lib:
    return Lib(build(gcc, tmp_path_factory.mktemp("libvstig"), keys=32768))


@pytest.fixture(scope="session")
def small_lib(gcc: str, tmp_path_factory: pytest.TempPathFactory) -> Lib:
    return Lib(build(gcc, tmp_path_factory.mktemp("libvstig"), keys=4))
