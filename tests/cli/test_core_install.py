"""The core install alone (the wheel, no extras, a fresh venv) runs the gateway, and loads no extra's library.

The wheel carries the compiled data path (this machine compiles): the session runs on it, and the install stays
within its size goal (25 MB, `make bench`'s install group). The sdist installs where nothing compiles, pure
(tests/cli/test_sdist.py).

A lab's gateway PC installs `pip install vstig-hw`: bridge, sniff, record, replay,
decode, put and get must work there against real robots' media (a pty radio,
python-can's virtual bus), and a command that needs an extra must say which in
one line. The same session runs in the development venv too, where every extra
is installed: the gateway's commands must still not load numpy, numba,
matplotlib, zenoh or mcap.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import click
import pytest
from core_session import EXTRAS_LIBRARIES
from installs import build_wheel, fresh_venv, install, installed_bytes, installed_modules, site_packages

import vstig_hw.native
from vstig_cli.main import cli
from vstig_hw.capture.decoded import FAST_PATH_BYTES

SESSION = Path(__file__).with_name("core_session.py")
CORE_MB = 25  # the core install's size goal (benchmarks/bench_install.py)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_wheel(tmp_path_factory.mktemp("wheel"))


@pytest.fixture(scope="module")  # a wheel built and installed once: the tests that use it are slow
def core_python(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    python = fresh_venv(tmp_path_factory.mktemp("core-install") / "venv")
    install(python, str(wheel))
    return python


@pytest.mark.slow
def test_the_wheel_is_this_platforms_and_carries_the_compiled_data_path(wheel: Path) -> None:
    import zipfile

    assert wheel.name.endswith(f"-cp{sys.version_info.major}{sys.version_info.minor}-"
                               f"cp{sys.version_info.major}{sys.version_info.minor}-linux_x86_64.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert [n for n in names if n.startswith("vstig_hw/_vstig.") and n.endswith(".so")]
    assert not [n for n in names if n.endswith(".c")]  # the sdist carries the sources, not the wheel


@pytest.mark.slow
def test_the_core_install_stays_within_its_size_goal(core_python: Path) -> None:
    assert installed_bytes(core_python) <= CORE_MB * 1e6


def _session(python: Path, folder: Path) -> dict[str, Any]:
    done = subprocess.run([str(python), str(SESSION), str(folder)], capture_output=True, text=True, timeout=120,
                          check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    result: dict[str, Any] = json.loads(done.stdout)
    return result


@pytest.mark.slow
def test_the_core_install_brings_none_of_the_extras_libraries(core_python: Path) -> None:
    installed = installed_modules(core_python)
    assert {"vstig_hw", "vstig_cli", "can", "serial", "click"} <= installed
    assert not installed & set(EXTRAS_LIBRARIES)


@pytest.mark.slow
@pytest.mark.parametrize("venv", ["core", "development"])
def test_the_gateway_commands_run_and_load_no_extras_library(venv: str, request: pytest.FixtureRequest,
                                                             tmp_path: Path) -> None:
    python = request.getfixturevalue("core_python") if venv == "core" else Path(sys.executable)
    result = _session(python, tmp_path)
    if venv == "core":  # the installed wheel ran, not this tree
        assert Path(result["package"]).is_relative_to(site_packages(python))
    runs = result["runs"]
    for name, run in runs.items():
        assert run["code"] == 0, f"vstig {name}: {run['err']}"
    assert result["radio"]["1"] == 500  # the bridge carried the CAN robot's write to the radio robot
    sniffed = [json.loads(line) for line in runs["sniff"]["out"].splitlines()]
    assert any({"key": 2, "value": 777, "robot": 21, "sender": 21}.items() <= row.items() for row in sniffed)
    decoded = [json.loads(line) for line in runs["decode"]["out"].splitlines()]
    assert decoded and {(row["key"], row["value"], row["robot"]) for row in decoded} == {(1, 500, 21), (2, 777, 21)}
    assert runs["decode"]["err"].endswith(f": {len(decoded)} messages\n")  # record wrote, decode read them all
    assert runs["replay"]["err"].startswith(f"sent {len(decoded)} units")
    assert result["radio"]["2"] == 777  # heard only from the replayed capture
    assert runs["put"]["out"].startswith("put key=3 value=4242 timestamp=1 robot=99 on ")
    assert result["radio"]["3"] == 4242
    assert runs["get"]["out"] == "key=2 value=777 timestamp=1 robot=21\n"
    assert result["imported"] == []
    assert result["pure"] == ("" if venv == "core" else vstig_hw.native.why_pure)  # the wheel's compiled path ran


@pytest.mark.slow
def test_vstig_help_in_the_core_install_lists_every_command(core_python: Path) -> None:
    shown = subprocess.run([str(core_python.with_name("vstig")), "--help"], capture_output=True, text=True,
                           timeout=60, check=False)
    assert shown.returncode == 0, shown.stderr
    listed = shown.stdout.split("Commands:")[1].split()
    assert set(cli.list_commands(click.Context(cli))) <= set(listed)


@pytest.mark.slow
@pytest.mark.parametrize(("args", "line"), [
    (["sim", "--runs", "1"], "vstig sim needs the sim extra: pip install 'vstig-hw[sim]'"),
    (["analyze", "CAPTURE"], "vstig analyze needs the analyze extra: pip install 'vstig-hw[analyze]'"),
    (["bridge", "can:virtual:lab", "zenoh:lab", "--robot-id", "5"],
     "a zenoh: link needs the zenoh extra: pip install 'vstig-hw[zenoh]'"),
    (["record", "can:virtual:lab", "-o", "OUT.mcap", "--for", "1"],
     "vstig record -o OUT.mcap needs the mcap extra: pip install 'vstig-hw[mcap]'"),
    (["demo", "--gateways", "2"], "vstig demo --gateways 2 needs the zenoh extra: pip install 'vstig-hw[zenoh]'"),
    (["sniff", "can:virtual:lab", "--foxglove", "0", "--for", "1"],
     "--foxglove needs the live extra: pip install 'vstig-hw[live]'"),
], ids=["sim", "analyze", "zenoh-link", "record-mcap", "demo-zenoh", "sniff-foxglove"])
def test_a_command_beyond_the_core_names_its_extra_in_one_line(core_python: Path, tmp_path: Path, args: list[str],
                                                                line: str) -> None:
    capture = tmp_path / "bus.log"
    capture.write_text("(1700000000.000000) can0 615#0001000200030015\n")
    paths = {"CAPTURE": str(capture), "OUT.mcap": str(tmp_path / "out.mcap")}
    args = [paths.get(arg, arg) for arg in args]
    line = line.replace("OUT.mcap", paths["OUT.mcap"])
    done = subprocess.run([str(core_python.with_name("vstig")), *args], capture_output=True, text=True, timeout=60,
                          check=False)
    assert (done.returncode, done.stdout, done.stderr) == (1, "", f"Error: {line}\n")
    assert not (tmp_path / "out.mcap").exists()


# `vstig ARGS` with the modules named in argv[1] (comma-separated) unimportable, as if not installed: a module
# set to None in sys.modules cannot be imported. The last line on stderr says whether numpy was loaded.
_WITHOUT = """
import sys
for name in filter(None, sys.argv[1].split(",")):
    sys.modules[name] = None
from vstig_cli.main import run
status = run(sys.argv[2:])
print("numpy loaded:", sys.modules.get("numpy") is not None, file=sys.stderr)
sys.exit(status)
"""


def _run_without(missing: list[str], args: list[str]) -> tuple[subprocess.CompletedProcess[str], bool]:
    done = subprocess.run([sys.executable, "-c", _WITHOUT, ",".join(missing), *args], capture_output=True,
                          text=True, timeout=120, check=False)
    *said, loaded = done.stderr.splitlines(keepends=True)
    done.stderr = "".join(said)
    return done, loaded == "numpy loaded: True\n"


def test_analyze_plot_without_matplotlib_names_the_analyze_extra(tmp_path: Path) -> None:
    """numpy alone runs `analyze`; `--plot` needs matplotlib too, and says so before reading anything."""
    capture = tmp_path / "bus.log"
    capture.write_text("(1700000000.000000) can0 615#0001000200030015\n")
    plot = tmp_path / "p.png"
    done, _ = _run_without(["matplotlib"], ["analyze", str(capture), "--plot", str(plot)])
    assert (done.returncode, done.stdout) == (1, "")
    assert done.stderr == "Error: vstig analyze --plot needs the analyze extra: pip install 'vstig-hw[analyze]'\n"
    assert not plot.exists()


def test_decode_of_a_big_candump_log_without_numpy_gives_the_same_messages(tmp_path: Path) -> None:
    """A log past FAST_PATH_BYTES takes numpy's path where numpy is installed, the line-by-line one where not."""
    log = tmp_path / "big.log"
    lines = [f"({1700000000 + i // 1000}.{i % 1000 * 1000:06d}) can0 {0x600 | (i % 2) << 8 | i % 40:03X}#"
             f"{(i % 2) << 15 | i % 300:04X}{i * 7 % 65536:04X}{i % 65535 + 1:04X}{i % 40:04X}\n"
             for i in range(30_000)]
    log.write_text("".join(lines))
    assert log.stat().st_size > FAST_PATH_BYTES
    with_numpy, loaded = _run_without([], ["decode", str(log), "--format", "jsonl"])
    without, loaded_anyway = _run_without(["numpy"], ["decode", str(log), "--format", "jsonl"])
    assert with_numpy.returncode == without.returncode == 0, without.stderr
    assert (loaded, loaded_anyway) == (True, False)
    rows = [json.loads(line) for line in without.stdout.splitlines()]
    assert len(rows) == 30_000 and rows == [json.loads(line) for line in with_numpy.stdout.splitlines()]
