"""The compiled data path (vstig_hw._vstig), as this install has it: built by `pip install -e .` where gcc and
Python's headers are (tests/sysdeps.sh installs them). Its tests skip under VSTIG_PURE=1 (the pure pass of `make
test`), and where it is not built they skip naming why, or fail under VSTIG_REQUIRE_PEERS=1."""

from __future__ import annotations

from types import ModuleType

import pytest
from required import missing

from vstig_hw.native import PURE_ENV, native, why_pure


@pytest.fixture(scope="session")
def compiled() -> ModuleType:
    if native is None:
        if why_pure.startswith(PURE_ENV):
            pytest.skip(f"{why_pure}: the pure-Python path only")
        missing(f"the compiled data path ({why_pure}; `pip install -e .` builds it with gcc and the Python headers)")
    return native
