"""vstig beside the ros2 extra's wheels: started once, its signals taken over in its first lines.

The wheels install `ros_wheels_bootstrapper.pth`, which re-executes every Python of the
environment to set LD_LIBRARY_PATH unless `_ROS_WHEELS_BOOTSTRAP_COMPLETE` is set. vstig
runs with it set (`make test`, and the how-to tells users); only its ROS 2 node process
gets the wheels' library path, computed (`vstig_hw.ros2msgs.ros_environment`). Here vstig
runs as a user's would: the guard set, no library path, in this venv (which has the extra).
"""

from __future__ import annotations

import os
import signal
import statistics
import subprocess
import sysconfig
import time
from pathlib import Path

import pytest
from peers import VSTIG, PtyPeer, catches, start_vstig, wait_for
from required import missing

from vstig_hw.ros2msgs import BOOTSTRAP_GUARD

BOOTSTRAPPER = Path(sysconfig.get_paths()["purelib"]) / "ros_wheels_bootstrapper.pth"


@pytest.fixture(autouse=True)
def _wheels_installed() -> None:
    if not BOOTSTRAPPER.is_file():
        missing("the ros2 extra (its ros_wheels_bootstrapper.pth)")


def _env(guarded: bool) -> dict[str, str]:
    """This environment as a user's: no library path from the wheels; their guard set or not."""
    env = {name: value for name, value in os.environ.items() if name not in (BOOTSTRAP_GUARD, "LD_LIBRARY_PATH")}
    return {**env, BOOTSTRAP_GUARD: "1"} if guarded else env


def _interpreters(guarded: bool) -> int:
    """How many Pythons `vstig --version` started: each reports its `encodings` import under -X importtime."""
    done = subprocess.run([VSTIG, "--version"], env={**_env(guarded), "PYTHONPROFILEIMPORTTIME": "1"},
                          capture_output=True, text=True, timeout=60, check=True)
    return sum(line.rstrip().endswith("| encodings") for line in done.stderr.splitlines())


def test_vstig_starts_one_python_where_the_wheels_would_start_two() -> None:
    assert _interpreters(guarded=True) == 1
    assert _interpreters(guarded=False) == 2  # the wheels' re-execution is real here: the count above could fail


@pytest.fixture
def radio() -> PtyPeer:
    peer = PtyPeer()
    yield peer  # type: ignore[misc]
    peer.close()


def _until_it_catches(radio: PtyPeer, guarded: bool) -> tuple[subprocess.Popen[str], float]:
    """A bridge started, and the seconds until it caught SIGTERM."""
    start = time.perf_counter()
    process = start_vstig("bridge", f"serial:{radio.path}", "--robot-id", "1", env=_env(guarded))
    wait_for(lambda: catches(process.pid, signal.SIGTERM) or process.poll() is not None, 30,
             step=lambda: time.sleep(0.001))
    return process, time.perf_counter() - start


def test_a_stop_the_moment_vstig_runs_is_clean_and_comes_sooner_than_with_the_wheels_restart(radio: PtyPeer) -> None:
    times: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(5):  # alternated, so the machine's load weighs on both alike
        for guarded in (True, False):
            process, took = _until_it_catches(radio, guarded)
            times[guarded].append(took)
            environ = Path(f"/proc/{process.pid}/environ").read_bytes()
            process.send_signal(signal.SIGTERM)
            _out, err = process.communicate(timeout=10)
            assert process.returncode == 0, err
            assert "Traceback" not in err, err
            # re-executed, a process holds the environment the bootstrapper made (the wheels' library path)
            assert (b"ros_rclpy.libs" in environ) is (not guarded)
    # the restart is a whole interpreter's start (~20 ms idle); the medians keep a loaded machine's outliers out
    assert statistics.median(times[True]) < statistics.median(times[False]), times
