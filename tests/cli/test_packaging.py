"""A wheel must carry every subpackage and its extras must match the code: pyproject lists both by hand."""

from __future__ import annotations

import tomllib
from importlib.metadata import distribution, packages_distributions
from pathlib import Path

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
