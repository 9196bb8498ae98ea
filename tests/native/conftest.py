"""The compiled data path (vstig_hw._vstig), as this install has it: built by `pip install -e .` where gcc and
Python's headers are (tests/sysdeps.sh installs them).

Where it must be there, its tests fail when it is not loaded, whatever the reason: under CI=true, under
VSTIG_REQUIRE_NATIVE=1 (`make test` sets it for its main pass) and under VSTIG_REQUIRE_PEERS=1. Elsewhere they skip
under VSTIG_PURE=1 (the pure pass of `make test`), and skip naming why where it is not built."""

from __future__ import annotations

import os
from types import ModuleType

import pytest
from required import missing

from vstig_hw.native import PURE_ENV, native, why_pure

REQUIRE_ENV = "VSTIG_REQUIRE_NATIVE"


def required_by() -> str | None:
    """What says the compiled path must be here (the differential tests never skip there), or None."""
    if os.environ.get("CI", "").lower() == "true":
        return "CI=true"
    for name in (REQUIRE_ENV, "VSTIG_REQUIRE_PEERS"):
        if os.environ.get(name) == "1":
            return f"{name}=1"
    return None


@pytest.fixture(scope="session")
def compiled() -> ModuleType:
    if native is None:
        requirement = required_by()
        if requirement is not None:
            pytest.fail(f"{requirement} but the compiled data path is not loaded ({why_pure}): its differential "
                        "tests must run (`pip install -e .` builds it with gcc and the Python headers)")
        if why_pure.startswith(PURE_ENV):
            pytest.skip(f"{why_pure}: the pure-Python path only")
        missing(f"the compiled data path ({why_pure}; `pip install -e .` builds it with gcc and the Python headers)")
    return native
