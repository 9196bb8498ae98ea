"""The UML runner retries a kernel that dies at boot, and only that.

A real early death is easy to cause: a kernel given too little memory exits in its
early memory setup ("Too few physical memory!") before PID 1 runs, as the flaky
boots do. A wrapper boots the real kernel that way for the first N tries.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import uml

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _needs_uml() -> None:
    reason = uml.unavailable_reason()
    if reason:
        if os.environ.get("VSTIG_REQUIRE_SOCKETCAN") == "1":
            pytest.fail(f"VSTIG_REQUIRE_SOCKETCAN=1 but {reason}")
        pytest.skip(reason)


def _dying_kernel(tmp_path: Path, deaths: int) -> str:
    """A kernel command that dies at boot `deaths` times (the real kernel, starved of memory), then boots."""
    real = uml.uml_binary()
    wrapper = tmp_path / "linux-dies-at-boot"
    wrapper.write_text(f"""#!/bin/sh
n=$(( $(cat {tmp_path}/boots 2>/dev/null || echo 0) + 1 ))
echo $n > {tmp_path}/boots
shift  # the runner's mem=...
if [ $n -le {deaths} ]; then exec {real} mem=1M "$@"; fi
exec {real} mem=1G "$@"
""")
    wrapper.chmod(0o755)
    return str(wrapper)


def _test_file(tmp_path: Path, body: str) -> str:
    path = tmp_path / "cases" / "test_case.py"
    path.parent.mkdir()
    path.write_text(f"def test_case() -> None:\n    {body}\n")
    return str(path)


def test_a_boot_that_dies_before_running_anything_is_retried(tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    run = uml.run([_test_file(tmp_path, "assert True"), "-q"], work, binary=_dying_kernel(tmp_path, deaths=1))
    assert run.exit_code == 0, run.explain()
    assert run.boots == 2 and (tmp_path / "boots").read_text().strip() == "2"


def test_it_gives_up_after_the_retries_and_shows_the_kernel_log(tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    run = uml.run([_test_file(tmp_path, "assert True"), "-q"], work, binary=_dying_kernel(tmp_path, deaths=99))
    assert run.exit_code is None
    assert run.boots == 1 + uml.BOOT_RETRIES
    assert f"died at boot {run.boots} times" in run.status
    assert "Too few physical memory" in run.explain()  # the kernel's own last words


def test_a_failing_test_inside_the_guest_fails_without_a_retry(tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    run = uml.run([_test_file(tmp_path, "assert 1 == 2"), "-q"], work, binary=_dying_kernel(tmp_path, deaths=0))
    assert run.exit_code == 1, run.explain()
    assert run.boots == 1 and "1 failed" in run.pytest_log
