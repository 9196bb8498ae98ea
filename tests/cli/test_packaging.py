"""A wheel must carry every subpackage and its extras must match the code: pyproject lists both by hand."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from importlib.metadata import distribution, packages_distributions
from pathlib import Path

import pytest
from installs import PIP_TIMEOUT, clean_copy
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from vstig_hw.extras import EXTRAS

ROOT = Path(__file__).resolve().parents[2]


def test_every_subpackage_is_listed_in_pyproject() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    on_disk = {
        ".".join(init.parent.relative_to(ROOT).parts)
        for init in (ROOT / "vstig_hw").rglob("__init__.py")
    }
    assert on_disk <= listed, f"add to [tool.setuptools] packages: {sorted(on_disk - listed)}"
    assert config["package-dir"]["vstig_cli"] == "cli"


def _installed(name: str) -> bool:
    """Installed by an installer, not metadata carried inside another wheel (ROS 2's wheels hold the egg-info of
    the colcon build they came from, which names the module's ROS package: rclpy beside ros-rclpy)."""
    return distribution(name).read_text("INSTALLER") is not None


def test_each_extra_names_the_libraries_pyproject_installs_with_it() -> None:
    """What a missing extra is told by (`vstig_hw.extras`) and what pip installs for it are the same libraries."""
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    distributions = packages_distributions()
    for extra, modules in EXTRAS.items():
        listed = {canonicalize_name(Requirement(line).name) for line in extras[extra]}
        assert {canonicalize_name(d) for module in modules for d in distributions[module] if _installed(d)} == listed, \
            extra
    (everything,) = extras["all"]
    assert Requirement(everything).extras == set(EXTRAS)
    assert "vstig-hw[all]" in extras["test"]  # `make test` runs every command and link kind


@pytest.mark.slow
def test_building_the_package_prints_no_setuptools_warning(tmp_path: Path) -> None:
    """`make demo` opens with the install's output: a data file outside a declared package (the C sources, the IDL
    folders) made setuptools print a screenful of warnings there. CC=false: the compiled part is optional, and
    building it is not what this checks."""
    source = clean_copy(tmp_path / "source")
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--wheel-dir",
                           str(tmp_path / "dist"), str(source)], capture_output=True, text=True, timeout=PIP_TIMEOUT,
                          check=False, env={**os.environ, "CC": "false"})
    assert done.returncode == 0, done.stderr[-3000:]
    assert "BuildBackendWarning" not in done.stdout + done.stderr, done.stderr[-3000:]
    (wheel,) = (tmp_path / "dist").glob("vstig_hw-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    data = {name for name in names if not name.endswith(".py") and ".dist-info/" not in name}
    interfaces = {path.relative_to(source).as_posix() for path in source.glob("vstig_hw/ros2msgs/*/*.idl")}
    assert len(interfaces) >= 9  # Message, Entry, Change, Robot(s), TaggedMessage; Get, Put, Table
    assert data == {"vstig_hw/py.typed", "vstig_hw/_vstig.pyi", "vstig_hw/transports/fastdds_loopback.xml", *interfaces}
