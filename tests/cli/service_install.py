"""The vstig that `vstig service` tests run: one a unit with its own user can see.

`vstig service` names its own interpreter and script in the unit, and refuses them under /tmp or /var/tmp (a unit
with its own user gets a /tmp of its own, PrivateTmp=, where they would be missing). A checkout made there (a CI
clone, say) therefore gets a venv of its own elsewhere: the checkout installed whole, not editable (an editable
install reads the checkout, still under /tmp), built once per pyproject.toml, checkout and Python under the
machine's cache, a lock letting concurrent sessions share it. Anywhere else the test session's own vstig serves.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import venv
from functools import cache
from pathlib import Path

from peers import VSTIG

ROOT = Path(__file__).resolve().parents[2]
TEMPORARY = (Path("/tmp"), Path("/var/tmp"))  # what PrivateTmp= replaces (cli/ops/unit.py)
CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "vstig-hw"
EXTRAS = "zenoh,metrics"  # what the units under test run: zenoh links, --metrics


def _under_temporary(path: Path) -> bool:
    return any(path.resolve().is_relative_to(folder.resolve()) for folder in TEMPORARY)


@cache
def service_vstig() -> str:
    """The vstig executable for `vstig service` (built on first use where the checkout is under /tmp)."""
    if not any(map(_under_temporary, (ROOT, Path(VSTIG), Path(sys.executable)))):
        return VSTIG
    key = hashlib.sha256(b"\0".join([(ROOT / "pyproject.toml").read_bytes(), str(ROOT).encode(),
                                     sys.version.encode(), EXTRAS.encode()])).hexdigest()[:16]
    folder = CACHE / f"service-venv-{key}"
    CACHE.mkdir(parents=True, exist_ok=True)
    with open(folder.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / ".built").exists():
            shutil.rmtree(folder, ignore_errors=True)
            venv.create(folder, with_pip=True, clear=True)
            # CC=false: the pure path serves (the unit's tests relay a few messages); no compile, and nothing
            # written into the checkout
            done = subprocess.run([str(folder / "bin" / "python"), "-m", "pip", "install", "--quiet",
                                   "--disable-pip-version-check", f"{ROOT}[{EXTRAS}]"],
                                  capture_output=True, text=True, timeout=600, check=False,
                                  env={**os.environ, "CC": "false"})
            if done.returncode:
                raise RuntimeError(f"installing {ROOT} into {folder} failed:\n{done.stderr[-4000:]}")
            (folder / ".built").write_text(f"{ROOT}\n")
    return str(folder / "bin" / "vstig")
