"""Install size and time: `pip install vstig-hw` (the core) and `vstig-hw[all]`, each into a fresh venv.

The core's anchor is its dependencies alone (pyproject's list without vstig-hw), the
goal being at most 25 MB and 1.5x their install time; `all`'s anchor is the core.
Every wheel is fetched or built into a local wheelhouse first, and every install
reads only that folder, so no download is timed: the figures are what pip spends
unpacking and byte-compiling. Size is everything the install put in the venv's
site-packages (bytecode included). The core and its dependencies are installed
twice, alternately, and the faster of each kept.
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .registry import Result, benchmark

_REPO = Path(__file__).resolve().parents[1]
_MB = 1e6
_ROUNDS = 2


@benchmark("install")
def sizes_and_times() -> Iterator[Result]:
    sys.path.insert(0, str(_REPO / "tests" / "cli"))
    from installs import build_wheel, core_dependencies, fresh_venv, install, installed_bytes, wheelhouse

    with tempfile.TemporaryDirectory(prefix="vstig-install-") as tmp:
        folder = Path(tmp)
        wheel = str(build_wheel(folder))
        local = wheelhouse(folder / "wheelhouse", f"{wheel}[all]")

        def measure(name: str, *requirements: str) -> tuple[float, float]:
            python = fresh_venv(folder / name)
            seconds = install(python, *requirements, pip_args=local)
            return seconds, installed_bytes(python) / _MB

        deps_s, core_s = float("inf"), float("inf")
        for _ in range(_ROUNDS):
            seconds, deps_mb = measure("deps", *core_dependencies())
            deps_s = min(deps_s, seconds)
            seconds, core_mb = measure("core", wheel)
            core_s = min(core_s, seconds)
        all_s, all_mb = measure("all", f"{wheel}[all]")
    yield Result("install.core_mb", core_mb, "MB", "its dependencies alone", deps_mb)
    yield Result("install.core_seconds", core_s, "s", "its dependencies alone", deps_s)
    yield Result("install.all_mb", all_mb, "MB", "the core install", core_mb)
    yield Result("install.all_seconds", all_s, "s", "the core install", core_s)
