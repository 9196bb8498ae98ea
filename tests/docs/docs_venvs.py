"""The venvs the first hour's pages run in: the one `make demo` builds (the core, no extra), or the core and the
extras a block installs itself.

README.md and docs/getting-started.md are what a newcomer pastes after `make demo`, whose venv holds the core
alone. Their shell blocks run in such a venv, so a block that needs an extra fails unless it installs it in one
visible line (`pip install 'vstig-hw[zenoh]'`); such a block runs in a venv of the core and those extras, where its
own pip line finds them installed. Each venv is built once per pyproject.toml, checkout and Python (their hash names
its folder under the machine's cache) and reused by every later session; a lock lets concurrent sessions share it.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import re
import shutil
import subprocess
import sys
import venv
from pathlib import Path

from docs_blocks import ROOT

FIRST_HOUR = (ROOT / "README.md", ROOT / "docs" / "getting-started.md")
CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "vstig-hw"
PIP_TIMEOUT_S = 600
# A block's own install line: `pip install 'vstig-hw[zenoh]'` (or `-e '.[zenoh]'` in a clone).
_EXTRA_INSTALL = re.compile(r"^\s*pip install (?:-e )?['\"]?(?:vstig-hw|\.)\[([\w,-]+)\]", re.MULTILINE)


def installed_extras(script: str) -> tuple[str, ...]:
    """The extras a shell script installs itself, sorted."""
    return tuple(sorted({extra for found in _EXTRA_INSTALL.finditer(script) for extra in found[1].split(",")}))


def venv_folder(extras: tuple[str, ...]) -> Path:
    """The venv of this checkout with the core and `extras` installed, built on first use."""
    key = hashlib.sha256(b"\0".join([(ROOT / "pyproject.toml").read_bytes(), str(ROOT).encode(),
                                     sys.version.encode(), *(e.encode() for e in extras)])).hexdigest()[:16]
    folder = CACHE / f"docs-venv-{'-'.join(extras) or 'core'}-{key}"
    CACHE.mkdir(parents=True, exist_ok=True)
    with open(folder.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / ".built").exists():
            _build(folder, extras)
    return folder


def _build(folder: Path, extras: tuple[str, ...]) -> None:
    shutil.rmtree(folder, ignore_errors=True)
    venv.create(folder, with_pip=True, clear=True)  # with pip, as `make demo`'s: a block's own pip line uses it
    target = f"{ROOT}[{','.join(extras)}]" if extras else str(ROOT)
    # Editable, as `make demo` installs, so the venv runs this tree as it is now. CC=false: an editable install
    # copies the compiled data path it builds into the tree, over the one the running tests have loaded; the
    # venv imports the tree's own build (or runs pure where there is none).
    done = subprocess.run([str(folder / "bin" / "python"), "-m", "pip", "install", "--quiet",
                           "--disable-pip-version-check", "-e", target],
                          capture_output=True, text=True, timeout=PIP_TIMEOUT_S, check=False,
                          env={**os.environ, "CC": "false"})
    if done.returncode:
        raise RuntimeError(f"installing {target} into {folder} failed:\n{done.stdout[-2000:]}{done.stderr[-4000:]}")
    (folder / ".built").write_text(target + "\n")


def environment(folder: Path, base: dict[str, str]) -> dict[str, str]:
    """`base` as `. folder/bin/activate` leaves it, with this session's own venv off PATH."""
    ours = str(Path(sys.executable).parent)
    path = [part for part in base.get("PATH", "").split(os.pathsep) if part and part != ours]
    return {**base, "PATH": os.pathsep.join([str(folder / "bin"), *path]), "VIRTUAL_ENV": str(folder)}
