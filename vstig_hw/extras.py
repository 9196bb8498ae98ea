"""Which optional libraries each extra brings, and the one line a user sees when one is missing.

The core install (`pip install vstig-hw`) is what the gateway needs: bridge, sniff,
record, replay, decode, put and get. A command or link kind that needs more asks
`require` before it does any work, so a lab PC without the extra gets
`vstig sim needs the sim extra: pip install 'vstig-hw[sim]'` and exit 1, not an
ImportError halfway through. The check finds modules without importing them.
"""

from __future__ import annotations

from collections.abc import Iterable
from importlib.util import find_spec

__all__ = ["EXTRAS", "MissingExtra", "install_hint", "missing", "require"]

# The modules each extra of pyproject.toml installs (tests hold the two equal).
EXTRAS: dict[str, tuple[str, ...]] = {
    "zenoh": ("zenoh",),
    "sim": ("numpy", "numba", "matplotlib"),
    "analyze": ("numpy", "matplotlib"),
    "mcap": ("mcap", "rosbags"),
    "live": ("foxglove",),
    "metrics": ("prometheus_client",),
    "ros2": ("rclpy", "rmw_fastrtps_cpp", "diagnostic_msgs", "rosidl_generator_c", "rosidl_generator_py",
             "rosidl_typesupport_c", "rosidl_typesupport_fastrtps_c", "rosidl_typesupport_introspection_c"),
}


class MissingExtra(RuntimeError):
    """A command or link kind needs an extra that is not installed (a runtime failure: exit 1)."""


def install_hint(extra: str) -> str:
    return f"pip install 'vstig-hw[{extra}]'"


def missing(modules: Iterable[str]) -> list[str]:
    """The modules of `modules` that cannot be imported here."""
    return [name for name in modules if find_spec(name) is None]


def require(extra: str, who: str, modules: Iterable[str] | None = None) -> None:
    """Raise MissingExtra (`<who> needs the <extra> extra: pip install ...`) unless `modules` can be imported.

    `modules` defaults to everything the extra installs; a command that needs only part of it
    (`analyze` without `--plot`: numpy alone) names that part.
    """
    if missing(EXTRAS[extra] if modules is None else modules):
        raise MissingExtra(f"{who} needs the {extra} extra: {install_hint(extra)}")
