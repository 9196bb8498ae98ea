"""The sdist carries libvstig's sources (firmware_spec/) and installs where nothing compiles: nothing in it needs a
C compiler at install time (a machine whose compiler fails still gets the package)."""

from __future__ import annotations

import subprocess
import tarfile
from pathlib import Path

import pytest
from installs import ROOT, SOURCES, clean_copy, fresh_venv, install, site_packages


@pytest.mark.slow  # two fresh venvs and a build backend from the package index
def test_the_sdist_carries_libvstig_and_installs_without_a_compiler(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    source = clean_copy(tmp_path / "source", (*SOURCES, "MANIFEST.in", "firmware_spec"))
    builder = fresh_venv(tmp_path / "builder")
    install(builder, "setuptools>=77")  # the build backend pyproject.toml names
    done = subprocess.run([str(builder), "-c", "import sys; from setuptools import build_meta as b; "
                           "print(b.build_sdist(sys.argv[1]))", str(tmp_path / "dist")],
                          cwd=source, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    sdist = tmp_path / "dist" / done.stdout.split()[-1]
    with tarfile.open(sdist) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    libvstig = {p.relative_to(ROOT).as_posix() for p in (ROOT / "firmware_spec" / "libvstig").rglob("*")
                if p.is_file() and "build" not in p.parts and "__pycache__" not in p.parts}
    assert libvstig and libvstig <= names, sorted(libvstig - names)
    assert {"firmware_spec/SPEC.md", "firmware_spec/vectors/receive.json"} <= names

    user = fresh_venv(tmp_path / "user")
    for variable in ("CC", "CXX", "LDSHARED"):  # a compiler that always fails: nothing may need one
        monkeypatch.setenv(variable, "false")
    install(user, "--no-deps", str(sdist))
    assert (site_packages(user) / "vstig_hw" / "engine.py").exists()
