"""`import vstig_hw` stays light: the API (threads, link modules, python-can) loads only when first used."""

from __future__ import annotations

import subprocess
import sys


def _loaded(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", f"{code}\nimport sys\nprint(' '.join(sys.modules))"],
                         capture_output=True, text=True, check=True, timeout=60).stdout
    return set(out.split())


def test_importing_the_package_loads_no_api_and_no_link_library() -> None:
    loaded = _loaded("import vstig_hw")
    assert not {"vstig_hw.api", "vstig_hw.api.swarm", "vstig_hw.gateway", "can", "serial", "asyncio"} & loaded


def test_join_and_aio_load_on_first_use() -> None:
    assert {"vstig_hw.api.swarm", "vstig_hw.gateway.node"} <= _loaded("import vstig_hw\nvstig_hw.join")
    assert "vstig_hw.api.aio" in _loaded("import vstig_hw.aio")
    assert "vstig_hw.api.aio" in _loaded("import vstig_hw\nvstig_hw.aio.join")


def test_the_api_loads_no_extras_library() -> None:
    loaded = _loaded("import vstig_hw, vstig_hw.aio, vstig_hw.api.virtual\nvstig_hw.join")
    assert not {"zenoh", "numpy", "numba", "matplotlib", "mcap"} & loaded
