"""The sdist carries libvstig's sources (firmware_spec/) and the compiled data path's glue, and installs where nothing
compiles: the extension is optional, so a machine whose compiler fails still gets the package, pure Python, and its
gateway relays."""

from __future__ import annotations

import subprocess
import tarfile
from pathlib import Path

import pytest
from installs import ROOT, clean_copy, fresh_venv, install, site_packages


@pytest.mark.slow  # two fresh venvs and a build backend from the package index
def test_the_sdist_carries_libvstig_and_installs_without_a_compiler(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    source = clean_copy(tmp_path / "source")
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
    glue = {p.relative_to(ROOT).as_posix() for p in (ROOT / "vstig_hw" / "_cext").iterdir()}
    assert glue and glue | {"setup.py"} <= names, sorted(glue - names)

    user = fresh_venv(tmp_path / "user")
    for variable in ("CC", "CXX", "LDSHARED"):  # a compiler that always fails: nothing may need one
        monkeypatch.setenv(variable, "false")
    install(user, str(sdist))
    assert (site_packages(user) / "vstig_hw" / "engine.py").exists()
    assert not list(site_packages(user).glob("vstig_hw/_vstig*.so"))  # nothing compiled, and it installed
    done = subprocess.run([str(user), "-c", _RELAY_ONE], capture_output=True, text=True, timeout=60, check=False,
                          cwd=tmp_path)  # not this tree, whose vstig_hw `python -c` would import
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["the compiled data path is not built here (No module named 'vstig_hw._vstig')",
                                        "Message(PUT, key=1, value=2, timestamp=3, robot=4)"]


# One message from one python-can virtual bus to another through an engine Node; prints why the path is pure.
_RELAY_ONE = """
import time
import can
from vstig_hw import Message, Op
from vstig_hw.framing.can import CanFraming, CanIdScheme
from vstig_hw.gateway.node import Node
from vstig_hw.links import parse
from vstig_hw.native import why_pure
print(why_pure)
links = [parse(spec).build() for spec in ("can:virtual:a", "can:virtual:b")]
robot, far = can.Bus(interface="virtual", channel="a"), can.Bus(interface="virtual", channel="b")
framing = CanFraming(CanIdScheme(), sender=4)
with Node(links, 9, budget=None) as node:
    robot.send(framing.encode(Message(Op.PUT, 1, 2, 3, 4))[0])
    heard = []
    end = time.monotonic() + 10
    while not heard and time.monotonic() < end:  # the node relays on its own threads
        heard.extend(framing.feed(f) for f in iter(lambda: far.recv(0.05), None))
print(heard[0][0])
"""
