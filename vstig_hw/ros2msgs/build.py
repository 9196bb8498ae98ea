"""Build the `vstig_msgs` ROS 2 interfaces from the IDL beside this module, with the `ros2` extra's rosidl.

rosidl generates the C structs, the C type supports (the dispatcher, Fast DDS's
CDR, introspection) and the Python classes; gcc and g++ compile them against the
headers and libraries the ROS 2 wheels put in the environment's prefix. The
result is laid out as a site-packages folder holds installed ROS 2 wheels:

    <prefix>/vstig_msgs/                Python classes and the C extension rclpy imports
    <prefix>/ros_vstig_msgs.libs/       the shared libraries (what rcl loads by name)

Run in a child process (`python -m vstig_hw.ros2msgs build`), so rosidl's
templates and warnings never load into a gateway; ~2 s of generation and ~5 s of
compiling on two cores.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from collections.abc import Iterable
from pathlib import Path

__all__ = ["IDL_FILES", "LIB_DIR", "PACKAGE", "BuildError", "build", "compilers_missing", "ros_prefixes"]

PACKAGE = "vstig_msgs"
LIB_DIR = f"ros_{PACKAGE}.libs"  # the ROS 2 wheels' bootstrapper puts site-packages/ros_*.libs on the library path
HERE = Path(__file__).resolve().parent
IDL_FILES = tuple(sorted(f"{kind}/{path.name}" for kind in ("msg", "srv") for path in (HERE / kind).glob("*.idl")))
_DEPENDENCIES = ("service_msgs", "builtin_interfaces")  # every service's Event type carries theirs
_TYPESUPPORTS = ("typesupport_c", "typesupport_fastrtps_c", "typesupport_introspection_c")


class BuildError(RuntimeError):
    """The interfaces cannot be built here; the message says what is missing, in one line."""


def ros_prefixes() -> list[Path]:
    """Where ROS 2 is installed: $AMENT_PREFIX_PATH (a sourced ROS), else this environment's prefix (wheels)."""
    listed = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return listed or [Path(sys.prefix)]


def compilers_missing() -> list[str]:
    """What the build needs and this machine lacks: a C and a C++ compiler, and Python's headers."""
    missing = [tool for tool in (os.environ.get("CC", "gcc"), os.environ.get("CXX", "g++")) if not shutil.which(tool)]
    if not (Path(sysconfig.get_paths()["include"]) / "Python.h").is_file():
        missing.append("Python's headers (Python.h)")
    return missing


def _generate(out: Path) -> None:
    """rosidl's generators, called as its `rosidl generate` would (its CLI refuses the wheels' duplicate
    entry points), into out/<generator>/."""
    os.environ.setdefault("AMENT_PREFIX_PATH", os.pathsep.join(map(str, ros_prefixes())))
    from rosidl_cli.command.hash.api import generate_type_hashes
    from rosidl_generator_c.cli import GenerateC
    from rosidl_generator_py.cli import GeneratePython
    from rosidl_typesupport_c.cli import GenerateCTypesupport
    from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
    from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport

    files = [f"{HERE}:{name}" for name in IDL_FILES]
    includes = [str(prefix / "share") for prefix in ros_prefixes()]
    hashes = generate_type_hashes(package_name=PACKAGE, interface_files=files, include_paths=includes,
                                  output_path=out / "type_description")
    GenerateC("c").generate(PACKAGE, files, includes, output_path=out / "c", type_description_files=hashes)
    GeneratePython("py", typesupport_implementations=["rosidl_typesupport_c"]).generate(
        PACKAGE, files, includes, output_path=out / "py")
    for name, generator in zip(_TYPESUPPORTS, (GenerateCTypesupport, GenerateFastRTPSCTypesupport,
                                               GenerateIntrospectionCTypesupport), strict=True):
        generator(name).generate(PACKAGE, files, includes, output_path=out / name)


def _sources(folder: Path, suffix: str) -> list[str]:
    return sorted(str(path) for path in folder.rglob(f"*{suffix}"))


def _compile(jobs: Iterable[list[str]]) -> None:
    """Run the compiler commands two at a time (what a lab PC has); BuildError with the first failure's output."""
    pending = list(jobs)
    while pending:
        running = [(argv, subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
                   for argv in pending[:2]]
        del pending[:2]
        for argv, process in running:
            output, _ = process.communicate()
            if process.returncode:
                raise BuildError(f"compiling the {PACKAGE} interfaces failed ({Path(argv[0]).name} exit "
                                 f"{process.returncode}): {output.strip()[-1500:]}")


def build(prefix: Path, work: Path) -> None:
    """Generate and compile the interfaces into `prefix` (laid out as site-packages), using `work` for the rest."""
    missing = compilers_missing()
    if missing:
        raise BuildError(f"building the {PACKAGE} ROS 2 interfaces needs {', '.join(missing)} "
                         "(Debian: apt install gcc g++ python3-dev)")
    generated = work / "generated"
    _generate(generated)
    headers = work / "include" / PACKAGE
    for name in ("c", *_TYPESUPPORTS[1:]):
        shutil.copytree(generated / name, headers, dirs_exist_ok=True,
                        ignore=lambda _, names: [n for n in names if n.endswith((".c", ".cpp"))])
    libs = prefix / LIB_DIR
    package = prefix / PACKAGE
    libs.mkdir(parents=True)
    package.mkdir()
    ros = ros_prefixes()
    include = [f"-I{work / 'include'}", f"-I{sysconfig.get_paths()['include']}"]
    for root in ros:
        include += [f"-I{root / 'include'}", *(f"-I{d}" for d in sorted((root / "include").glob("*/")))]
    link = [f"-L{libs}", *(f"-L{root / 'lib'}" for root in ros),
            "-Wl,-rpath,$ORIGIN", *(f"-Wl,-rpath,{root / 'lib'}" for root in ros)]
    cc, cxx = os.environ.get("CC", "gcc"), os.environ.get("CXX", "g++")
    common = ["-O2", "-fPIC", "-shared", *include]

    def lib(name: str) -> tuple[str, ...]:  # named (soname) so that loading it by path satisfies rcl's load by name
        return f"-Wl,-soname,lib{PACKAGE}__{name}.so", "-o", str(libs / f"lib{PACKAGE}__{name}.so")

    def deps(kind: str) -> list[str]:
        return [f"-l{dependency}__{kind}" for dependency in _DEPENDENCIES]

    strict = ["-Wl,--no-undefined"]  # a missing library fails here, not when rclpy loads the type
    _compile([[cc, *common, *_sources(generated / "c", ".c"), *link, *strict, *deps("rosidl_generator_c"),
               "-lrosidl_runtime_c", "-lrcutils", *lib("rosidl_generator_c")]])
    generator_c = f"-l{PACKAGE}__rosidl_generator_c"
    numpy_include = f"-I{_numpy_include()}"
    _compile([
        [cc, *common, *_sources(generated / "typesupport_introspection_c", ".c"), *link, *strict, generator_c,
         *deps("rosidl_typesupport_introspection_c"), "-lrosidl_typesupport_introspection_c", "-lrosidl_runtime_c",
         *lib("rosidl_typesupport_introspection_c")],
        [cxx, "-std=c++17", *common, *_sources(generated / "typesupport_fastrtps_c", ".cpp"), *link, *strict,
         generator_c, *deps("rosidl_typesupport_fastrtps_c"), *deps("rosidl_generator_c"),
         "-lrosidl_typesupport_fastrtps_c", "-lrosidl_typesupport_fastrtps_cpp", "-lfastcdr", "-lrmw",
         "-lrosidl_runtime_c", "-lrcutils", *lib("rosidl_typesupport_fastrtps_c")],
        [cxx, "-std=c++17", *common, *_sources(generated / "typesupport_c", ".cpp"), *link, *strict, generator_c,
         *deps("rosidl_typesupport_c"), "-lrosidl_typesupport_c", "-lrosidl_runtime_c", "-lrcpputils", "-lrcutils",
         *lib("rosidl_typesupport_c")],
        # Python's own symbols come from the interpreter that loads these: no --no-undefined
        [cc, *common, numpy_include, *_sources(generated / "py", "_s.c"), *link, generator_c,
         *deps("rosidl_generator_py"), *deps("rosidl_generator_c"), "-lrosidl_runtime_c",
         *lib("rosidl_generator_py")],
    ])
    extension = f"{PACKAGE}_s__rosidl_typesupport_c"
    _compile([[cc, *common, str(generated / "py" / f"_{PACKAGE}_s.ep.rosidl_typesupport_c.c"), *link,
               f"-Wl,-rpath,$ORIGIN/../{LIB_DIR}", f"-l{PACKAGE}__rosidl_generator_py",
               f"-l{PACKAGE}__rosidl_typesupport_c", generator_c, "-lrosidl_runtime_c",
               "-o", str(package / f"{extension}.so")]])
    for kind in ("msg", "srv"):
        shutil.copytree(generated / "py" / kind, package / kind, ignore=shutil.ignore_patterns("*.c"))
    (package / "__init__.py").write_text(f'"""The {PACKAGE} ROS 2 interfaces, built by vstig-hw from its IDL."""\n')


def _numpy_include() -> str:
    import numpy  # rosidl_generator_py's C code includes numpy's headers; the ros2 extra brings numpy

    return str(numpy.get_include())
