"""Fresh installs of this tree, as a user gets them: a wheel, a new venv, pip.

Shared by the core-only test (tests/cli/test_core_install.py) and `make bench`
(benchmarks/bench_install.py). The venvs are made without pip of their own:
this interpreter's pip installs into them (`pip --python`), so a venv's
site-packages holds exactly what the install brought, and pip's configuration
and cache are the machine's.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import tomllib
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# What the wheel and the sdist are built from (setup.py builds the compiled data path from libvstig in
# firmware_spec/). Copied to a clean folder first: an old build/ in the tree can put files that no longer exist
# into a wheel, and a compiled module built in place would go in as it is.
SOURCES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "vstig_hw", "cli", "firmware_spec")
PIP_TIMEOUT = 600.0


def core_dependencies() -> list[str]:
    """The core install's requirements, as pyproject.toml lists them."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return list(project["dependencies"])


def _pip(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([sys.executable, "-m", "pip", "--disable-pip-version-check", *args],
                          capture_output=True, text=True, timeout=PIP_TIMEOUT, check=False,
                          env=None if env is None else {**os.environ, **env})
    if done.returncode:
        raise RuntimeError(f"pip {' '.join(args)} failed:\n{done.stdout[-2000:]}{done.stderr[-4000:]}")
    return done


def clean_copy(source: Path, names: tuple[str, ...] = SOURCES) -> Path:
    """The files and folders `names` of this tree copied into `source`, without bytecode or build folders."""
    for name in names:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "build", "*.so"))
        else:
            source.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, source / name)
    return source


def build_wheel(folder: Path) -> Path:
    """A wheel of this tree (no dependencies fetched), built from a clean copy under `folder`."""
    source = clean_copy(folder / "source")
    _pip("wheel", "--quiet", "--no-deps", "--wheel-dir", str(folder / "dist"), str(source))
    (wheel,) = (folder / "dist").glob("vstig_hw-*.whl")
    return wheel


def wheelhouse(folder: Path, *requirements: str) -> tuple[str, ...]:
    """Every wheel `requirements` need, fetched or built into `folder` once; returns the pip options
    that make an install read that folder alone (nothing downloaded while it is timed)."""
    _pip("wheel", "--quiet", "--wheel-dir", str(folder), *requirements)
    return ("--no-index", "--find-links", str(folder))


def fresh_venv(path: Path) -> Path:
    """A new venv with nothing installed (not even pip); returns its python."""
    venv.create(path, with_pip=False, clear=True)
    return path / "bin" / "python"


def install(python: Path, *requirements: str, pip_args: tuple[str, ...] = (),
            env: dict[str, str] | None = None) -> float:
    """pip-install `requirements` into the venv of `python` (with `env` added to the environment: CC=false, no
    compiler); returns the seconds it took."""
    start = time.perf_counter()
    _pip("--python", str(python), "install", "--quiet", *pip_args, *requirements, env=env)
    return time.perf_counter() - start


def site_packages(python: Path) -> Path:
    (folder,) = python.parent.parent.glob("lib/python3*/site-packages")
    return folder


def installed_bytes(python: Path) -> int:
    """The size of everything in the venv's site-packages (bytecode included, as pip leaves it)."""
    return sum(f.stat().st_size for f in site_packages(python).rglob("*") if f.is_file() and not f.is_symlink())


def installed_modules(python: Path) -> set[str]:
    """Top-level names importable from the venv's site-packages."""
    return {p.name.removesuffix(".py") for p in site_packages(python).iterdir()
            if not p.name.endswith((".dist-info", ".pth")) and p.name != "__pycache__"}
